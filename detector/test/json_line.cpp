#include "json_line.hpp"

#include <cctype>
#include <utility>
#include <variant>
#include <vector>

namespace json_line {
namespace {

using Value = std::variant<std::string, long long, bool>;

class Reader {
 public:
  explicit Reader(const std::string& text) : s_(text) {}

  bool object(std::vector<std::pair<std::string, Value>>& members, std::string& why) {
    if (!take('{')) return fail(why, "expected '{'");
    if (take('}')) return end(why);
    do {
      std::string key;
      if (!string(key)) return fail(why, "expected a key string");
      if (!take(':')) return fail(why, "expected ':' after \"" + key + "\"");
      Value v;
      if (!value(v)) return fail(why, "bad value for \"" + key + "\"");
      members.emplace_back(key, v);
    } while (take(','));
    if (!take('}')) return fail(why, "expected ',' or '}'");
    return end(why);
  }

 private:
  bool end(std::string& why) { return i_ == s_.size() || fail(why, "text after the object"); }
  bool fail(std::string& why, const std::string& what) {
    why = what + " at offset " + std::to_string(i_);
    return false;
  }
  bool take(char c) {
    if (i_ < s_.size() && s_[i_] == c) {
      ++i_;
      return true;
    }
    return false;
  }
  bool string(std::string& out) {
    if (!take('"')) return false;
    while (i_ < s_.size() && s_[i_] != '"') {
      if (s_[i_] == '\\' || static_cast<unsigned char>(s_[i_]) < 0x20) return false;
      out += s_[i_++];
    }
    return take('"');
  }
  bool value(Value& out) {
    if (i_ < s_.size() && s_[i_] == '"') {
      std::string str;
      if (!string(str)) return false;
      out = str;
      return true;
    }
    if (s_.compare(i_, 4, "true") == 0) {
      i_ += 4;
      out = true;
      return true;
    }
    const size_t start = i_;
    take('-');
    const size_t digits = i_;
    while (i_ < s_.size() && std::isdigit(static_cast<unsigned char>(s_[i_]))) ++i_;
    if (i_ == digits) return false;
    if (s_[digits] == '0' && i_ - digits > 1) return false;  // JSON has no leading zeros
    out = std::stoll(s_.substr(start, i_ - start));
    return true;
  }

  const std::string& s_;
  size_t i_ = 0;
};

bool is_int(const Value& v) { return std::holds_alternative<long long>(v); }

}  // namespace

std::optional<Datagram> parse(const std::string& text, std::string& why) {
  std::vector<std::pair<std::string, Value>> m;
  if (!Reader(text).object(m, why)) return std::nullopt;
  Datagram d;
  if (m.empty() || m[0].first != "color" || !std::holds_alternative<std::string>(m[0].second)) {
    why = "first key must be \"color\" with a string";
    return std::nullopt;
  }
  d.colour = std::get<std::string>(m[0].second);
  if (d.colour != "red" && d.colour != "blue") {
    why = "unknown colour \"" + d.colour + "\"";
    return std::nullopt;
  }
  if (m.size() >= 2 && m[1].first == "none") {
    const bool t_ok = m.size() == 2 || (m.size() == 3 && m[2].first == "t" && is_int(m[2].second));
    if (!std::holds_alternative<bool>(m[1].second) || !t_ok) {
      why = "expected {\"color\":..,\"none\":true} (optionally \"t\")";
      return std::nullopt;
    }
    d.none = true;
    return d;
  }
  const char* keys[] = {"color", "x", "y", "area", "t"};
  if (m.size() != 5) {
    why = "expected keys color, x, y, area, t";
    return std::nullopt;
  }
  for (size_t k = 1; k < 5; ++k) {
    if (m[k].first != keys[k] || !is_int(m[k].second)) {
      why = std::string("key ") + std::to_string(k) + " must be the integer \"" + keys[k] + "\"";
      return std::nullopt;
    }
  }
  d.x = std::get<long long>(m[1].second);
  d.y = std::get<long long>(m[2].second);
  d.area = std::get<long long>(m[3].second);
  d.t = std::get<long long>(m[4].second);
  if (d.area <= 0 || d.t < 0) {
    why = "area must be > 0 and t >= 0";
    return std::nullopt;
  }
  return d;
}

}  // namespace json_line
