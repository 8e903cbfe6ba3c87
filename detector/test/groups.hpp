// The test groups of detector_test; each is one CTest test.
#pragma once

#include <string>

namespace groups {

void detection();
void datagram();
void settings(const std::string& shipped_conf);
void options();
void cli(const std::string& binary);
void udp(const std::string& binary);
void bad_inputs(const std::string& binary);

}  // namespace groups
