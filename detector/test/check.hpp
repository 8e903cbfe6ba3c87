// A small tally for the test program: each expectation passes or fails with a
// description; a group ends by printing "N passed, N failed".
#pragma once

#include <sstream>
#include <string>

namespace check {

// Records one expectation; a failure is printed at once with its description.
bool expect(bool ok, const std::string& what);

// Prints the closing "N passed, N failed" line; returns the process exit status.
int summary();

int failures();

// Builds descriptions: check::text("centre ", x, ",", y).
template <class... Parts>
std::string text(const Parts&... parts) {
  std::ostringstream out;
  (out << ... << parts);
  return out.str();
}

}  // namespace check
