// Detector settings: colour ranges, minimum areas, kernel sizes, frame size.
// Read from a `key = value` text (detector.conf documents every key) and
// overridable key by key from the command line. Parsing is pure: text in,
// settings or a problem naming the culprit out.
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace detector {

// A closed interval of 8-bit channel values. For hue, lo > hi means the range
// wraps through 0: 170..7 is 170..179 together with 0..7.
struct Range {
  int lo = 0;
  int hi = 0;
  bool operator==(const Range& o) const { return lo == o.lo && hi == o.hi; }
};

// OpenCV's 8-bit HSV: hue 0..179 (degrees / 2), saturation and value 0..255.
struct ColourSpec {
  std::string name;
  Range hue;
  Range sat;
  Range val;
  double min_area = 0;  // px², in the configured frame size
  bool operator==(const ColourSpec& o) const {
    return name == o.name && hue == o.hue && sat == o.sat && val == o.val &&
           min_area == o.min_area;
  }
};

struct Settings {
  int frame_width = 320;   // frames are resized to this; 0 x 0 keeps their own size
  int frame_height = 240;
  int erode = 3;           // odd kernel sizes in pixels; 1 switches the step off
  int dilate = 3;
  double max_fps = 30;     // continuous runs never go faster; 0 means no limit
  std::vector<ColourSpec> colours;  // red, then blue
  bool operator==(const Settings& o) const {
    return frame_width == o.frame_width && frame_height == o.frame_height &&
           erode == o.erode && dilate == o.dilate && max_fps == o.max_fps &&
           colours == o.colours;
  }
};

// A problem, if any: a one-line message naming the key or line at fault.
using Problem = std::optional<std::string>;

// The defaults, identical to the shipped detector.conf.
Settings default_settings();

// Sets one key, e.g. ("red.min_area", "300").
Problem apply_setting(Settings& settings, const std::string& key, const std::string& value);

// Applies every `key = value` line of a config text; `#` starts a comment.
// origin names the text in messages ("detector.conf" gives "detector.conf:7: ...").
Problem apply_config(Settings& settings, const std::string& text, const std::string& origin);

// Rules that involve more than one key, checked once everything is applied.
Problem check_settings(const Settings& settings);

// The settings in the config format, every key once, in the documented order.
std::string to_config_text(const Settings& settings);

}  // namespace detector
