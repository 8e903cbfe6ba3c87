#include "options.hpp"

#include <cerrno>
#include <cstdlib>

namespace detector {

const char* const kUsage =
    "usage: detector --input SRC [--udp HOST:PORT] [--print] [--once] [--config FILE]\n"
    "                [--debug-out DIR] [--set KEY=VALUE]... [--frame-size WxH] [--frames N]\n"
    "                [--verbose] [--show-config] [--help]\n"
    "  SRC: /dev/videoN or a camera index, a GStreamer pipeline (contains '!'),\n"
    "       a video file, an image file, or a directory of images (sorted by name)\n"
    "  --udp       send datagrams to HOST:PORT (HOST defaults to 127.0.0.1);\n"
    "              without --udp and --print they go to 127.0.0.1:5005\n"
    "  --print     one JSON line per frame and colour on stdout\n"
    "  --once      one frame (each image of a directory once), then exit\n"
    "  --config    settings file (key = value); see detector.conf\n"
    "  --set       override one settings key, e.g. --set red.min_area=300\n"
    "  --frame-size  same as --set frame.width=W --set frame.height=H\n"
    "  --frames    stop after N frames\n"
    "  --debug-out write an annotated PNG per frame into DIR\n"
    "  --verbose   let OpenCV, GStreamer and codec libraries print their own diagnostics\n"
    "  --show-config  print the effective settings and exit\n";

namespace {

std::optional<long> parse_long(const std::string& s) {
  if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
  errno = 0;
  const long v = std::strtol(s.c_str(), nullptr, 10);
  if (errno != 0) return std::nullopt;
  return v;
}

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

}  // namespace

std::optional<Destination> parse_destination(const std::string& text) {
  std::string host = kDefaultDestination.host;
  std::string port_text = text;
  if (!text.empty() && text[0] == '[') {
    const auto close = text.find("]:");
    if (close == std::string::npos || close == 1) return std::nullopt;
    host = text.substr(1, close - 1);
    port_text = text.substr(close + 2);
  } else if (const auto colon = text.rfind(':'); colon != std::string::npos) {
    if (text.find(':') != colon) return std::nullopt;  // bare IPv6 needs brackets
    if (colon > 0) host = text.substr(0, colon);
    port_text = text.substr(colon + 1);
  }
  const auto port = parse_long(port_text);
  if (!port || *port < 1 || *port > 65535) return std::nullopt;
  return Destination{host, static_cast<int>(*port)};
}

Problem parse_options(const std::vector<std::string>& args, Options& out) {
  out = Options{};
  for (size_t i = 0; i < args.size(); ++i) {
    std::string name = args[i];
    std::optional<std::string> inline_value;
    if (const auto eq = name.find('='); name.rfind("--", 0) == 0 && eq != std::string::npos) {
      inline_value = name.substr(eq + 1);
      name = name.substr(0, eq);
    }
    auto value = [&]() -> std::optional<std::string> {
      if (inline_value) return inline_value;
      if (i + 1 < args.size()) return args[++i];
      return std::nullopt;
    };
    auto flag = [&](bool& target) -> Problem {
      if (inline_value) return name + " takes no value, got " + quoted(*inline_value);
      target = true;
      return std::nullopt;
    };
    Problem problem;
    if (name == "--print") {
      problem = flag(out.print);
    } else if (name == "--once") {
      problem = flag(out.once);
    } else if (name == "--help" || name == "-h") {
      problem = flag(out.help);
    } else if (name == "--show-config") {
      problem = flag(out.show_config);
    } else if (name == "--verbose") {
      problem = flag(out.verbose);
    } else if (name == "--input" || name == "--udp" || name == "--config" ||
               name == "--debug-out" || name == "--set" || name == "--frame-size" ||
               name == "--frames") {
      const auto v = value();
      if (!v) return "option " + name + " needs a value";
      if (name == "--input") {
        if (v->empty()) return "--input: empty source";
        out.input = *v;
      } else if (name == "--udp") {
        const auto dest = parse_destination(*v);
        if (!dest) return "--udp: expected [HOST:]PORT with PORT within 1..65535, got " + quoted(*v);
        out.udp = dest;
      } else if (name == "--config") {
        out.config_path = *v;
      } else if (name == "--debug-out") {
        if (v->empty()) return "--debug-out: empty directory name";
        out.debug_out = *v;
      } else if (name == "--set") {
        const auto eq = v->find('=');
        if (eq == std::string::npos || eq == 0)
          return "--set: expected KEY=VALUE, got " + quoted(*v);
        out.overrides.push_back({v->substr(0, eq), v->substr(eq + 1), "--set " + *v});
      } else if (name == "--frame-size") {
        const auto x = v->find('x');
        const auto w = x == std::string::npos ? std::nullopt : parse_long(v->substr(0, x));
        const auto h = x == std::string::npos ? std::nullopt : parse_long(v->substr(x + 1));
        if (!w || !h) return "--frame-size: expected WIDTHxHEIGHT, got " + quoted(*v);
        out.overrides.push_back({"frame.width", std::to_string(*w), "--frame-size " + *v});
        out.overrides.push_back({"frame.height", std::to_string(*h), "--frame-size " + *v});
      } else {
        const auto n = parse_long(*v);
        if (!n || *n < 1) return "--frames: expected a count >= 1, got " + quoted(*v);
        out.frames = *n;
      }
    } else {
      return "unknown option " + quoted(args[i]) + " (try --help)";
    }
    if (problem) return problem;
  }
  if (out.help || out.show_config) return std::nullopt;
  if (out.input.empty()) return "missing --input SRC (try --help)";
  if (!out.udp && !out.print) out.udp = kDefaultDestination;
  return std::nullopt;
}

Problem build_settings(const Options& options, const std::string& config_text, Settings& out) {
  out = default_settings();
  if (!options.config_path.empty()) {
    if (auto problem = apply_config(out, config_text, options.config_path)) return problem;
  }
  for (const auto& o : options.overrides) {
    if (auto problem = apply_setting(out, o.key, o.value)) return o.origin + ": " + *problem;
  }
  return check_settings(out);
}

}  // namespace detector
