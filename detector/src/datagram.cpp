#include "datagram.hpp"

namespace detector {

std::string datagram(const Detection& d, long long t_ms) {
  // Colour names are fixed identifiers ("red", "blue"): nothing to escape.
  std::string out = "{\"color\":\"" + d.colour + "\",";
  if (!d.found) return out + "\"none\":true}";
  return out + "\"x\":" + std::to_string(d.x) + ",\"y\":" + std::to_string(d.y) +
         ",\"area\":" + std::to_string(d.area) + ",\"t\":" + std::to_string(t_ms) + "}";
}

}  // namespace detector
