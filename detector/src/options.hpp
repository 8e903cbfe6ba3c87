// The detector's command line (SPEC §7b) and its few additions:
//   detector --input SRC [--udp HOST:PORT] [--print] [--once] [--config FILE]
//            [--debug-out DIR] [--set KEY=VALUE]... [--frame-size WxH]
//            [--frames N] [--verbose] [--show-config] [--help]
// Parsing is pure: arguments in, options or a problem naming the culprit out.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "settings.hpp"

namespace detector {

struct Destination {
  std::string host;
  int port = 0;
  bool operator==(const Destination& o) const { return host == o.host && port == o.port; }
};

inline const Destination kDefaultDestination{"127.0.0.1", 5005};

// One settings key set from the command line; origin is the option as given,
// for messages ("--frame-size 5x5").
struct Override {
  std::string key;
  std::string value;
  std::string origin;
};

struct Options {
  std::string input;
  std::optional<Destination> udp;  // after parsing: set unless --print came alone
  bool print = false;
  bool once = false;
  long frames = 0;                  // stop after this many frames; 0 means no limit
  std::string config_path;          // empty: the built-in defaults
  std::string debug_out;            // empty: no debug images
  std::vector<Override> overrides;  // in command-line order
  bool help = false;
  bool show_config = false;
  bool verbose = false;             // let OpenCV and codec libraries print their diagnostics
};

// "HOST:PORT", ":PORT" or "PORT" (host 127.0.0.1), "[IPv6]:PORT".
std::optional<Destination> parse_destination(const std::string& text);

// args excludes the program name. Options accept "--name value" and "--name=value".
Problem parse_options(const std::vector<std::string>& args, Options& out);

// Applies the config file's text (if any) then the command-line overrides to the
// defaults, then checks the result. config_text is read by the caller.
Problem build_settings(const Options& options, const std::string& config_text, Settings& out);

extern const char* const kUsage;

}  // namespace detector
