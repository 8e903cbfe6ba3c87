// A strict reader for the detector's datagrams (SPEC §7), written independently
// of the detector's own formatter so the tests check the format, not the code:
//   {"color":"red"|"blue","x":int,"y":int,"area":int,"t":int}
//   {"color":"red"|"blue","none":true}            ("t" may follow "none")
#pragma once

#include <optional>
#include <string>

namespace json_line {

struct Datagram {
  std::string colour;
  bool none = false;
  long long x = 0, y = 0, area = 0, t = 0;
};

// The datagram, or nothing with why set to the first thing wrong.
std::optional<Datagram> parse(const std::string& text, std::string& why);

}  // namespace json_line
