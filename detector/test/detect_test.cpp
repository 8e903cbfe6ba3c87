// The detection core against generated frames with known truth: targets on
// every background, shapes leaving the frame, two reds, distractor colours,
// minimum area, clean-up, resizing. Prints the centre error over the set.
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>

#include "check.hpp"
#include "detect.hpp"
#include "groups.hpp"
#include "scene.hpp"

using check::expect;
using check::text;
using detector::Detection;
using detector::Detector;
using detector::Settings;
using scene::Background;

namespace {

const cv::Size kFrame(320, 240);
const Background kBackgrounds[] = {Background::plain, Background::noisy, Background::gradient,
                                   Background::warm_gradient};
constexpr size_t kRed = 0;
constexpr size_t kBlue = 1;

// Sensor noise that goes with each background.
double sigma_of(Background b) { return b == Background::noisy ? 8.0 : 2.0; }

struct ErrorStats {
  double max = 0;
  double sum = 0;
  int count = 0;
  double area_sum = 0;
  void add(double centre_error, double area_error) {
    max = std::max(max, centre_error);
    sum += centre_error;
    area_sum += area_error;
    ++count;
  }
};
ErrorStats stats;

std::uint64_t next_seed() {
  static std::uint64_t seed = 1;
  return seed++;
}

// The centre within 2 px and the area within 20 % for targets of 400 px² or
// more: the outline's area runs about half a perimeter below the pixel count,
// and noise nibbles the edges of colours near a range bound (tomato, hue 5).
void expect_at(const Detection& d, const scene::Truth& truth, const std::string& what) {
  if (!expect(d.found, what + ": " + d.colour + " found")) return;
  if (truth.area < 400) return;
  const double error = std::hypot(d.x - truth.x, d.y - truth.y);
  const double area_error = std::abs(d.area - truth.area) / truth.area;
  stats.add(error, area_error);
  expect(error <= 2.0, text(what, ": ", d.colour, " centre (", d.x, ",", d.y, ") vs truth (",
                            truth.x, ",", truth.y, "), error ", error, " px"));
  expect(area_error <= 0.20,
         text(what, ": ", d.colour, " area ", d.area, " vs truth ", truth.area));
}

void expect_none(const Detection& d, const std::string& what) {
  expect(!d.found, text(what, ": no ", d.colour, " expected, got (", d.x, ",", d.y, ") area ",
                        d.area));
}

std::vector<Detection> detect(const Settings& settings, const cv::Mat& image) {
  Detector detector(settings);
  return detector.detect(image);
}

void no_target() {
  const Settings s = detector::default_settings();
  for (Background b : kBackgrounds) {
    for (int i = 0; i < 3; ++i) {
      const auto sc = scene::render(kFrame, b, {}, sigma_of(b), next_seed());
      const auto found = detect(s, sc.image);
      expect(found.size() == 2, "two detections per frame");
      expect(found[kRed].colour == "red" && found[kBlue].colour == "blue", "red first, blue second");
      expect_none(found[kRed], text("empty ", scene::name_of(b)));
      expect_none(found[kBlue], text("empty ", scene::name_of(b)));
    }
  }
}

std::vector<scene::Shape> shapes_at(cv::Point2d c, cv::Scalar bgr) {
  return {scene::disk(c, 12, bgr), scene::disk(c, 20, bgr), scene::disk(c, 35, bgr),
          scene::rect(c, {30, 20}, bgr), scene::rect(c, {50, 50}, bgr),
          scene::rect(c, {80, 24}, bgr)};
}

void single_targets() {
  const Settings s = detector::default_settings();
  const cv::Point2d centres[] = {{40.3, 45.7}, {160, 120}, {251.5, 190.2}, {280.8, 60.1}};
  for (Background b : kBackgrounds) {
    for (size_t colour : {kRed, kBlue}) {
      const auto& paints = colour == kRed ? scene::kReds : scene::kBlues;
      for (const auto& paint : paints) {
        for (const auto& c : centres) {
          for (const auto& shape : shapes_at(c, paint.bgr)) {
            const auto sc = scene::render(kFrame, b, {shape}, sigma_of(b), next_seed());
            const auto found = detect(s, sc.image);
            const std::string what =
                text(paint.name, " ", shape.kind == scene::Shape::Kind::disk ? "disk " : "rect ",
                     shape.size.width, "x", shape.size.height, " at ", c, " on ", scene::name_of(b));
            expect_at(found[colour], sc.truths[0], what);
            expect_none(found[1 - colour], what);
          }
        }
      }
    }
  }
}

void both_colours() {
  const Settings s = detector::default_settings();
  for (Background b : kBackgrounds) {
    const auto sc = scene::render(kFrame, b,
                                  {scene::disk({90.5, 150.2}, 22, scene::kReds[0].bgr),
                                   scene::rect({230, 80}, {44, 36}, scene::kBlues[0].bgr)},
                                  sigma_of(b), next_seed());
    const auto found = detect(s, sc.image);
    expect_at(found[kRed], sc.truths[0], text("red and blue on ", scene::name_of(b)));
    expect_at(found[kBlue], sc.truths[1], text("red and blue on ", scene::name_of(b)));
  }
}

void partly_out_of_frame() {
  const Settings s = detector::default_settings();
  const std::vector<scene::Shape> cases = {
      scene::disk({-8, 100}, 25, scene::kReds[0].bgr),      // past the left edge
      scene::disk({325, 60}, 30, scene::kReds[1].bgr),      // past the right edge
      scene::disk({160, -10}, 28, scene::kReds[2].bgr),     // past the top
      scene::disk({100, 250}, 30, scene::kReds[3].bgr),     // past the bottom
      scene::disk({5, 5}, 40, scene::kReds[0].bgr),         // in a corner
      scene::rect({315, 200}, {40, 60}, scene::kReds[0].bgr),
      scene::disk({-10, 120}, 30, scene::kBlues[0].bgr),
      scene::rect({160, 235}, {90, 30}, scene::kBlues[1].bgr),
  };
  for (Background b : kBackgrounds) {
    for (const auto& shape : cases) {
      const auto sc = scene::render(kFrame, b, {shape}, sigma_of(b), next_seed());
      const size_t colour = shape.bgr == scene::kBlues[0].bgr || shape.bgr == scene::kBlues[1].bgr
                                ? kBlue
                                : kRed;
      const auto found = detect(s, sc.image);
      expect(sc.truths[0].area >= 400, "out-of-frame case keeps 400 px² in view");
      expect_at(found[colour], sc.truths[0],
                text("shape at ", shape.centre, " partly out of frame on ", scene::name_of(b)));
    }
  }
}

void larger_of_two_reds() {
  const Settings s = detector::default_settings();
  const cv::Point2d a(80, 80), b(230, 160);
  for (Background bg : kBackgrounds) {
    for (bool big_first : {true, false}) {
      const auto big = scene::disk(big_first ? a : b, 26, scene::kReds[0].bgr);
      const auto small = scene::disk(big_first ? b : a, 16, scene::kReds[1].bgr);
      const auto sc = scene::render(kFrame, bg, {small, big}, sigma_of(bg), next_seed());
      const auto found = detect(s, sc.image);
      expect_at(found[kRed], sc.truths[1],
                text("larger of two reds (big at ", big.centre, ") on ", scene::name_of(bg)));
    }
    // Two rectangles of close sizes: the larger still wins.
    const auto sc = scene::render(kFrame, bg,
                                  {scene::rect({70, 170}, {40, 40}, scene::kReds[0].bgr),
                                   scene::rect({240, 70}, {46, 40}, scene::kReds[0].bgr)},
                                  sigma_of(bg), next_seed());
    expect_at(detect(s, sc.image)[kRed], sc.truths[1],
              text("larger of two close-sized rects on ", scene::name_of(bg)));
  }
}

void distractors() {
  const Settings s = detector::default_settings();
  const Background backgrounds[] = {Background::plain, Background::noisy,
                                    Background::warm_gradient};
  for (const auto* list : {&scene::kRedDistractors, &scene::kBlueDistractors}) {
    for (const auto& paint : *list) {
      for (Background b : backgrounds) {
        const auto sc = scene::render(
            kFrame, b,
            {scene::disk({100, 110}, 45, paint.bgr), scene::rect({240, 150}, {70, 60}, paint.bgr)},
            sigma_of(b), next_seed());
        const auto found = detect(s, sc.image);
        const std::string what = text(paint.name, " only, on ", scene::name_of(b));
        expect_none(found[kRed], what);
        expect_none(found[kBlue], what);
      }
      // Beside a smaller real target, which must still be the one chosen.
      const auto sc = scene::render(
          kFrame, Background::noisy,
          {scene::disk({100, 110}, 50, paint.bgr), scene::disk({250, 60}, 14, scene::kReds[0].bgr),
           scene::disk({250, 180}, 14, scene::kBlues[0].bgr)},
          sigma_of(Background::noisy), next_seed());
      const auto found = detect(s, sc.image);
      expect_at(found[kRed], sc.truths[1], text("red beside a larger ", paint.name));
      expect_at(found[kBlue], sc.truths[2], text("blue beside a larger ", paint.name));
    }
  }
}

void minimum_area() {
  Settings s = detector::default_settings();
  const auto tiny = scene::render(kFrame, Background::plain,
                                  {scene::disk({160, 120}, 6, scene::kReds[0].bgr)}, 2, next_seed());
  expect_none(detect(s, tiny.image)[kRed], "red disk of ~110 px² under min_area 200");
  const auto small = scene::render(kFrame, Background::plain,
                                   {scene::disk({160, 120}, 10, scene::kReds[0].bgr)}, 2, next_seed());
  expect(detect(s, small.image)[kRed].found, "red disk of ~310 px² over min_area 200");
  s.colours[kRed].min_area = 500;
  expect_none(detect(s, small.image)[kRed], "red disk of ~310 px² under min_area 500");
  expect(detect(s, small.image)[kBlue].found == false, "min_area applies per colour");
}

void clean_up() {
  // A 4x4 red patch: gone after a 5-pixel erosion, kept with clean-up off.
  Settings s = detector::default_settings();
  s.colours[kRed].min_area = 1;
  const auto sc = scene::render(kFrame, Background::plain,
                                {scene::rect({100, 100}, {4, 4}, scene::kReds[0].bgr)}, 0, next_seed());
  s.erode = s.dilate = 5;
  expect_none(detect(s, sc.image)[kRed], "4x4 red patch removed by erode 5");
  s.erode = s.dilate = 1;
  expect(detect(s, sc.image)[kRed].found, "4x4 red patch kept with clean-up off");
}

void hue_wrap() {
  // Crimson sits above 170, red at 0: the default range wraps to take both.
  Settings s = detector::default_settings();
  const auto crimson = scene::render(kFrame, Background::plain,
                                     {scene::disk({160, 120}, 20, scene::kReds[1].bgr)}, 2, next_seed());
  expect(detect(s, crimson.image)[kRed].found, "crimson (hue 174) found with red.hue 170..7");
  s.colours[kRed].hue = {0, 7};
  expect_none(detect(s, crimson.image)[kRed], "crimson not found with red.hue 0..7");
}

void resizing() {
  // A 640x480 frame is taken down to the configured 320x240: offsets halve.
  const Settings s = detector::default_settings();
  const auto big = scene::render({640, 480}, Background::plain,
                                 {scene::disk({481.3, 121.7}, 40, scene::kReds[0].bgr),
                                  scene::rect({200, 360}, {80, 60}, scene::kBlues[0].bgr)},
                                 2, next_seed());
  Detector detector(s);
  const auto found = detector.detect(big.image);
  expect(detector.last_frame().size() == kFrame, "frame resized to frame.width x frame.height");
  for (size_t colour : {kRed, kBlue}) {
    scene::Truth half = big.truths[colour];
    half.x /= 2;
    half.y /= 2;
    half.area /= 4;
    expect_at(found[colour], half, "640x480 frame at 320x240");
  }
  Settings native = s;
  native.frame_width = native.frame_height = 0;
  const auto kept = detect(native, big.image);
  expect_at(kept[kRed], big.truths[0], "640x480 frame at its own size (frame 0x0)");
}

void other_pixel_formats() {
  const Settings s = detector::default_settings();
  const auto sc = scene::render(kFrame, Background::plain,
                                {scene::disk({100, 100}, 20, scene::kReds[0].bgr)}, 0, next_seed());
  cv::Mat grey, bgra;
  cv::cvtColor(sc.image, grey, cv::COLOR_BGR2GRAY);
  cv::cvtColor(sc.image, bgra, cv::COLOR_BGR2BGRA);
  const auto from_grey = detect(s, grey);
  expect_none(from_grey[kRed], "grey frame");
  expect_at(detect(s, bgra)[kRed], sc.truths[0], "BGRA frame");
}

}  // namespace

namespace groups {

void detection() {
  no_target();
  single_targets();
  both_colours();
  partly_out_of_frame();
  larger_of_two_reds();
  distractors();
  minimum_area();
  clean_up();
  hue_wrap();
  resizing();
  other_pixel_formats();
  std::cout << std::fixed << std::setprecision(2) << "centre error over " << stats.count
            << " targets >= 400 px2: max " << stats.max << " px, mean "
            << (stats.count ? stats.sum / stats.count : 0.0) << " px; mean area error "
            << (stats.count ? 100 * stats.area_sum / stats.count : 0.0) << " %" << std::endl;
}

}  // namespace groups
