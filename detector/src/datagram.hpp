// The detector's wire format (SPEC §7): one JSON object per frame and colour,
// sent as one UDP datagram and, with --print, as one line on stdout.
//   {"color":"red","x":12,"y":-30,"area":1534,"t":123456}
//   {"color":"blue","none":true}
#pragma once

#include <string>

#include "detect.hpp"

namespace detector {

// t_ms: milliseconds on the detector's monotonic clock, counted from its start,
// at the moment the frame was read. Keys always come in this order; no spaces.
std::string datagram(const Detection& detection, long long t_ms);

}  // namespace detector
