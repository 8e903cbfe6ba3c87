// The settings format: the shipped file, every key, and errors that name the
// culprit.
#include <fstream>
#include <sstream>

#include "check.hpp"
#include "groups.hpp"
#include "settings.hpp"

using check::expect;
using detector::Settings;

namespace {

bool mentions(const detector::Problem& p, const std::string& part) {
  return p && p->find(part) != std::string::npos && p->find('\n') == std::string::npos;
}

}  // namespace

namespace groups {

void settings(const std::string& shipped_conf) {
  std::ifstream in(shipped_conf);
  std::ostringstream text;
  text << in.rdbuf();
  expect(static_cast<bool>(in), "shipped config readable: " + shipped_conf);
  Settings shipped = detector::default_settings();
  const auto problem = detector::apply_config(shipped, text.str(), "detector.conf");
  expect(!problem, "shipped config parses: " + problem.value_or(""));
  expect(shipped == detector::default_settings(), "shipped config equals the built-in defaults");

  // Every key, round trip through the config text.
  Settings s = detector::default_settings();
  const auto all = detector::apply_config(s,
                                          "# comment line\n"
                                          "frame.width = 640   # trailing comment\n"
                                          "frame.height=480\n"
                                          "\n"
                                          "input.max_fps = 12.5\n"
                                          "morph.erode = 5\n"
                                          "morph.dilate = 7\n"
                                          "red.hue = 175..5\n"
                                          "red.sat = 100..250\n"
                                          "red.val = 90..255\n"
                                          "red.min_area = 350\n"
                                          "blue.hue = 95..125\n"
                                          "blue.sat = 80..255\n"
                                          "blue.val = 40..200\n"
                                          "blue.min_area = 50.5\n",
                                          "t.conf");
  expect(!all, "all keys apply: " + all.value_or(""));
  expect(s.frame_width == 640 && s.frame_height == 480 && s.max_fps == 12.5 && s.erode == 5 &&
             s.dilate == 7,
         "frame, fps and kernel keys");
  expect(s.colours[0].hue.lo == 175 && s.colours[0].hue.hi == 5 && s.colours[0].sat.lo == 100 &&
             s.colours[0].val.lo == 90 && s.colours[0].min_area == 350,
         "red keys");
  expect(s.colours[1].hue.lo == 95 && s.colours[1].val.hi == 200 && s.colours[1].min_area == 50.5,
         "blue keys");
  Settings again = detector::default_settings();
  expect(!detector::apply_config(again, detector::to_config_text(s), "round trip") && again == s,
         "to_config_text reads back to the same settings");

  // Problems name the file, the line and the key.
  struct Case {
    const char* text;
    const char* mentions;
  };
  const Case bad[] = {
      {"red.sat = 300..10\n", "t.conf:1: red.sat"},
      {"\n\nred.sat = 10..300\n", "t.conf:3: red.sat"},
      {"red.hue = 0..180\n", "red.hue"},
      {"red.hue = 7\n", "red.hue"},
      {"blue.val = 200..100\n", "blue.val"},
      {"red.min_area = -5\n", "red.min_area"},
      {"red.min_area = lots\n", "red.min_area"},
      {"morph.erode = 4\n", "morph.erode"},
      {"morph.dilate = 0\n", "morph.dilate"},
      {"frame.width = 10\n", "frame.width"},
      {"frame.height = 240px\n", "frame.height"},
      {"input.max_fps = -1\n", "input.max_fps"},
      {"green.hue = 40..80\n", "unknown key \"green.hue\""},
      {"red.hu = 0..10\n", "unknown key \"red.hu\""},
      {"just words\n", "t.conf:1: expected key = value"},
  };
  for (const auto& c : bad) {
    Settings t = detector::default_settings();
    const auto p = detector::apply_config(t, c.text, "t.conf");
    expect(mentions(p, c.mentions), std::string("config \"") + c.text + "\" fails naming " +
                                        c.mentions + ", got: " + p.value_or("(accepted)"));
  }
  Settings half = detector::default_settings();
  half.frame_width = 0;
  expect(mentions(detector::check_settings(half), "frame.width and frame.height"),
         "frame size 0 x 240 rejected");
  half.frame_height = 0;
  expect(!detector::check_settings(half), "frame size 0 x 0 (keep the source's) accepted");
}

}  // namespace groups
