// The command line, parsed without running anything.
#include "check.hpp"
#include "groups.hpp"
#include "options.hpp"

using check::expect;
using detector::Destination;
using detector::Options;

namespace {

bool fails_naming(const std::vector<std::string>& args, const std::string& part) {
  Options o;
  const auto p = detector::parse_options(args, o);
  return p && p->find(part) != std::string::npos && p->find('\n') == std::string::npos;
}

}  // namespace

namespace groups {

void options() {
  Options o;
  expect(!detector::parse_options({"--input", "cam.png"}, o), "input alone parses");
  expect(o.udp == Destination{"127.0.0.1", 5005} && !o.print,
         "neither --udp nor --print: UDP to 127.0.0.1:5005");

  expect(!detector::parse_options({"--input", "x", "--print"}, o) && o.print && !o.udp,
         "--print alone: no UDP");
  expect(!detector::parse_options({"--input", "x", "--print", "--udp", "10.0.0.2:6000"}, o) &&
             o.print && o.udp == Destination{"10.0.0.2", 6000},
         "--print and --udp together");
  expect(!detector::parse_options({"--input=x", "--udp=:7000", "--once", "--frames", "3"}, o) &&
             o.input == "x" && o.udp == Destination{"127.0.0.1", 7000} && o.once && o.frames == 3,
         "--name=value forms, default host");
  expect(!detector::parse_options({"--input", "x", "--config", "a.conf", "--debug-out", "dbg",
                                   "--set", "red.min_area=300", "--frame-size", "640x480"},
                                  o) &&
             o.config_path == "a.conf" && o.debug_out == "dbg" && o.overrides.size() == 3 &&
             o.overrides[0].key == "red.min_area" && o.overrides[0].value == "300" &&
             o.overrides[1].key == "frame.width" && o.overrides[2].value == "480",
         "config, debug-out, --set and --frame-size");
  expect(!detector::parse_options({"--help"}, o) && o.help, "--help needs no input");
  expect(!detector::parse_options({"--input", "x"}, o) && !o.verbose &&
             !detector::parse_options({"--input", "x", "--verbose"}, o) && o.verbose,
         "--verbose off by default, on when given");

  expect(detector::parse_destination("5005") == Destination{"127.0.0.1", 5005}, "bare port");
  expect(detector::parse_destination("localhost:1") == Destination{"localhost", 1}, "name:port");
  expect(detector::parse_destination("[::1]:5005") == Destination{"::1", 5005}, "[v6]:port");
  for (const char* bad : {"", "host", "host:", "host:0", "host:65536", "host:12ab", "::1:5005",
                          "[::1]5005", "h:-1"}) {
    expect(!detector::parse_destination(bad), std::string("destination rejected: \"") + bad + "\"");
  }

  expect(fails_naming({}, "missing --input"), "no arguments: names --input");
  expect(fails_naming({"--input"}, "--input needs a value"), "--input without value");
  expect(fails_naming({"--input", "x", "--udp", "nohost"}, "--udp"), "bad --udp named");
  expect(fails_naming({"--input", "x", "--udp", "h:99999"}, "\"h:99999\""), "bad port quoted");
  expect(fails_naming({"--input", "x", "--bogus"}, "unknown option \"--bogus\""), "unknown option");
  expect(fails_naming({"--input", "x", "--set", "red.min_area"}, "--set"), "--set without =");
  expect(fails_naming({"--input", "x", "--frame-size", "big"}, "--frame-size"), "bad frame size");
  expect(fails_naming({"--input", "x", "--frames", "0"}, "--frames"), "--frames 0");
  expect(fails_naming({"--input", "x", "--print=yes"}, "--print takes no value"), "flag with value");

  // Overrides apply over the config text, in order, and name their origin.
  detector::Settings s;
  expect(!detector::parse_options({"--input", "x", "--config", "c.conf", "--set",
                                   "red.min_area=300", "--set", "red.min_area=400"},
                                  o) &&
             !detector::build_settings(o, "red.min_area = 100\nblue.min_area = 90\n", s) &&
             s.colours[0].min_area == 400 && s.colours[1].min_area == 90,
         "command line overrides the config file, last one wins");
  detector::parse_options({"--input", "x", "--set", "red.sat=9..1"}, o);
  auto p = detector::build_settings(o, "", s);
  expect(p && p->find("--set red.sat=9..1: red.sat") == 0, "bad --set names itself: " + p.value_or(""));
  detector::parse_options({"--input", "x", "--frame-size", "5x5"}, o);
  p = detector::build_settings(o, "", s);
  expect(p && p->find("--frame-size 5x5") == 0, "bad --frame-size names itself: " + p.value_or(""));
  detector::parse_options({"--input", "x", "--config", "my.conf"}, o);
  p = detector::build_settings(o, "red.val = x\n", s);
  expect(p && p->find("my.conf:1: red.val") == 0, "config problems name file and line");
}

}  // namespace groups
