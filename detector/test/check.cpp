#include "check.hpp"

#include <iostream>

namespace check {
namespace {
int passed = 0;
int failed = 0;
}  // namespace

bool expect(bool ok, const std::string& what) {
  if (ok) {
    ++passed;
  } else {
    ++failed;
    std::cout << "FAIL: " << what << std::endl;
  }
  return ok;
}

int failures() { return failed; }

int summary() {
  std::cout << passed << " passed, " << failed << " failed" << std::endl;
  return failed == 0 ? 0 : 1;
}

}  // namespace check
