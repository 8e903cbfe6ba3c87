#include "settings.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace detector {
namespace {

std::string trim(const std::string& s) {
  const auto first = s.find_first_not_of(" \t\r");
  if (first == std::string::npos) return "";
  const auto last = s.find_last_not_of(" \t\r");
  return s.substr(first, last - first + 1);
}

std::optional<long> parse_int(const std::string& text) {
  const std::string s = trim(text);
  if (s.empty()) return std::nullopt;
  char* end = nullptr;
  errno = 0;
  const long v = std::strtol(s.c_str(), &end, 10);
  if (errno != 0 || *end != '\0') return std::nullopt;
  return v;
}

std::optional<double> parse_number(const std::string& text) {
  const std::string s = trim(text);
  if (s.empty()) return std::nullopt;
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  if (errno != 0 || *end != '\0' || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<Range> parse_range(const std::string& text) {
  const auto dots = text.find("..");
  if (dots == std::string::npos) return std::nullopt;
  const auto lo = parse_int(text.substr(0, dots));
  const auto hi = parse_int(text.substr(dots + 2));
  if (!lo || !hi) return std::nullopt;
  return Range{static_cast<int>(*lo), static_cast<int>(*hi)};
}

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

Problem bad(const std::string& key, const std::string& expected, const std::string& value) {
  return key + ": expected " + expected + ", got " + quoted(value);
}

ColourSpec* colour_named(Settings& settings, const std::string& name) {
  for (auto& c : settings.colours)
    if (c.name == name) return &c;
  return nullptr;
}

Problem apply_colour_key(ColourSpec& c, const std::string& key, const std::string& field,
                         const std::string& value) {
  if (field == "hue") {
    const auto r = parse_range(value);
    if (!r || r->lo < 0 || r->lo > 179 || r->hi < 0 || r->hi > 179)
      return bad(key, "LOW..HIGH within 0..179 (LOW > HIGH wraps through 0)", value);
    c.hue = *r;
    return std::nullopt;
  }
  if (field == "sat" || field == "val") {
    const auto r = parse_range(value);
    if (!r || r->lo < 0 || r->hi > 255 || r->lo > r->hi)
      return bad(key, "LOW..HIGH with 0 <= LOW <= HIGH <= 255", value);
    (field == "sat" ? c.sat : c.val) = *r;
    return std::nullopt;
  }
  if (field == "min_area") {
    const auto v = parse_number(value);
    if (!v || *v < 0) return bad(key, "an area in px² >= 0", value);
    c.min_area = *v;
    return std::nullopt;
  }
  return "unknown key " + quoted(key);
}

}  // namespace

Settings default_settings() {
  Settings s;
  // Red keeps clear of pink (hue <= 165 or saturation < 150), orange and brown
  // (hue >= 9) and dark reddish brown (value < 120); the tests pin each case.
  s.colours.push_back({"red", {170, 7}, {150, 255}, {120, 255}, 200});
  s.colours.push_back({"blue", {100, 130}, {120, 255}, {60, 255}, 200});
  return s;
}

Problem apply_setting(Settings& settings, const std::string& raw_key, const std::string& raw_value) {
  const std::string key = trim(raw_key);
  const std::string value = trim(raw_value);
  if (key == "frame.width" || key == "frame.height") {
    const auto v = parse_int(value);
    if (!v || (*v != 0 && (*v < 16 || *v > 8192)))
      return bad(key, "0 (keep the source's size) or a size in pixels within 16..8192", value);
    (key == "frame.width" ? settings.frame_width : settings.frame_height) = static_cast<int>(*v);
    return std::nullopt;
  }
  if (key == "morph.erode" || key == "morph.dilate") {
    const auto v = parse_int(value);
    if (!v || *v < 1 || *v > 31 || *v % 2 == 0)
      return bad(key, "an odd kernel size within 1..31 (1 switches it off)", value);
    (key == "morph.erode" ? settings.erode : settings.dilate) = static_cast<int>(*v);
    return std::nullopt;
  }
  if (key == "input.max_fps") {
    const auto v = parse_number(value);
    if (!v || *v < 0) return bad(key, "frames per second >= 0 (0 means no limit)", value);
    settings.max_fps = *v;
    return std::nullopt;
  }
  const auto dot = key.find('.');
  if (dot != std::string::npos) {
    if (ColourSpec* c = colour_named(settings, key.substr(0, dot)))
      return apply_colour_key(*c, key, key.substr(dot + 1), value);
  }
  return "unknown key " + quoted(key);
}

Problem apply_config(Settings& settings, const std::string& text, const std::string& origin) {
  std::istringstream in(text);
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    const auto hash = line.find('#');
    const std::string content = trim(line.substr(0, hash));
    if (content.empty()) continue;
    const std::string where = origin + ":" + std::to_string(number) + ": ";
    const auto eq = content.find('=');
    if (eq == std::string::npos) return where + "expected key = value, got " + quoted(content);
    if (auto problem = apply_setting(settings, content.substr(0, eq), content.substr(eq + 1)))
      return where + *problem;
  }
  return std::nullopt;
}

Problem check_settings(const Settings& s) {
  if ((s.frame_width == 0) != (s.frame_height == 0))
    return "frame.width and frame.height: both 0 or both sizes, got " +
           std::to_string(s.frame_width) + " x " + std::to_string(s.frame_height);
  return std::nullopt;
}

std::string to_config_text(const Settings& s) {
  std::ostringstream out;
  auto range = [](const Range& r) { return std::to_string(r.lo) + ".." + std::to_string(r.hi); };
  out << "frame.width = " << s.frame_width << "\n"
      << "frame.height = " << s.frame_height << "\n"
      << "input.max_fps = " << s.max_fps << "\n"
      << "morph.erode = " << s.erode << "\n"
      << "morph.dilate = " << s.dilate << "\n";
  for (const auto& c : s.colours) {
    out << c.name << ".hue = " << range(c.hue) << "\n"
        << c.name << ".sat = " << range(c.sat) << "\n"
        << c.name << ".val = " << range(c.val) << "\n"
        << c.name << ".min_area = " << c.min_area << "\n";
  }
  return out.str();
}

}  // namespace detector
