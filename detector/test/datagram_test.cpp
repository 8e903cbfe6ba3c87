// The wire format, byte for byte, and read back by the independent reader.
#include "check.hpp"
#include "datagram.hpp"
#include "groups.hpp"
#include "json_line.hpp"

using check::expect;

namespace groups {

void datagram() {
  detector::Detection red;
  red.colour = "red";
  red.found = true;
  red.x = 12;
  red.y = -30;
  red.area = 1534;
  const std::string found = detector::datagram(red, 123456);
  expect(found == R"({"color":"red","x":12,"y":-30,"area":1534,"t":123456})",
         "found form, exact bytes: " + found);

  detector::Detection blue;
  blue.colour = "blue";
  const std::string none = detector::datagram(blue, 99);
  expect(none == R"({"color":"blue","none":true})", "none form, exact bytes: " + none);

  std::string why;
  const auto back = json_line::parse(found, why);
  expect(back && back->colour == "red" && !back->none && back->x == 12 && back->y == -30 &&
             back->area == 1534 && back->t == 123456,
         "found form reads back: " + why);
  const auto back_none = json_line::parse(none, why);
  expect(back_none && back_none->colour == "blue" && back_none->none, "none form reads back: " + why);

  // The reader is strict, so the tests that rely on it mean something.
  for (const char* bad : {R"({"x":1,"color":"red","y":2,"area":3,"t":4})",
                          R"({"color":"red","x":1,"y":2,"area":3})",
                          R"({"color":"green","none":true})",
                          R"({"color":"red","x":1.5,"y":2,"area":3,"t":4})",
                          R"({"color":"red","none":true} )",
                          R"({"color":"red","none":false})",
                          R"({"color":"red","x":01,"y":2,"area":3,"t":4})"}) {
    expect(!json_line::parse(bad, why), std::string("reader rejects ") + bad);
  }
}

}  // namespace groups
