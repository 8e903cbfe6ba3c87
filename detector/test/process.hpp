// Runs a program to completion with its stdout and stderr captured, so the
// tests can drive the detector binary the way a user or script does.
#pragma once

#include <string>
#include <vector>

namespace process {

struct Outcome {
  int status = -1;     // exit status; -1 if killed by a signal or the timeout
  bool timed_out = false;
  std::string out;
  std::string err;
};

Outcome run(const std::vector<std::string>& argv, int timeout_ms = 20000);

// Lines of a text, without their newlines; a last line without one counts too.
std::vector<std::string> lines_of(const std::string& text);

}  // namespace process
