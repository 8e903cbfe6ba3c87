// detector_test GROUP [--conf detector.conf] [--binary path/to/detector]
// Runs one group of checks and ends with the line "N passed, N failed".
#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>

#include <iostream>
#include <string>

#include "check.hpp"
#include "groups.hpp"

int main(int argc, char** argv) {
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  cv::setNumThreads(1);
  if (argc < 2) {
    std::cerr << "usage: detector_test GROUP [--conf FILE] [--binary FILE]\n";
    return 2;
  }
  const std::string group = argv[1];
  std::string conf, binary;
  for (int i = 2; i + 1 < argc; i += 2) {
    const std::string name = argv[i];
    if (name == "--conf") conf = argv[i + 1];
    if (name == "--binary") binary = argv[i + 1];
  }
  if (group == "detection") {
    groups::detection();
  } else if (group == "datagram") {
    groups::datagram();
  } else if (group == "settings") {
    groups::settings(conf);
  } else if (group == "options") {
    groups::options();
  } else if (group == "cli") {
    groups::cli(binary);
  } else if (group == "udp") {
    groups::udp(binary);
  } else if (group == "bad_inputs") {
    groups::bad_inputs(binary);
  } else {
    std::cerr << "detector_test: unknown group \"" << group << "\"\n";
    return 2;
  }
  return check::summary();
}
