// Synthetic camera frames with known truth, generated at test time: a
// background, coloured disks and rectangles drawn in order (later ones cover
// earlier ones, shapes may leave the frame), then optional sensor noise. The
// truth of a shape is what stays visible of it: its pixel centroid relative to
// the frame centre and its pixel count.
#pragma once

#include <opencv2/core.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace scene {

enum class Background {
  plain,           // uniform mid grey
  noisy,           // grey with sensor noise and single-pixel red/blue/white specks
  gradient,        // dark-to-bright grey ramp
  warm_gradient,   // low-saturation beige to brown ramp, like a wooden floor
};

const char* name_of(Background background);

// A named BGR colour with the role it plays in the tests.
struct Paint {
  const char* name;
  cv::Scalar bgr;
};

// Colours the detector must find.
extern const std::vector<Paint> kReds;
extern const std::vector<Paint> kBlues;
// Colours close to red (pink, brown, orange, dark reddish brown) or to blue
// that must not count.
extern const std::vector<Paint> kRedDistractors;
extern const std::vector<Paint> kBlueDistractors;

struct Shape {
  enum class Kind { disk, rect };
  Kind kind;
  cv::Point2d centre;   // frame pixels, may lie outside the frame
  cv::Size2d size;      // disk: diameter in width; rect: width x height
  cv::Scalar bgr;
};

Shape disk(cv::Point2d centre, double radius, cv::Scalar bgr);
Shape rect(cv::Point2d centre, cv::Size2d size, cv::Scalar bgr);

struct Truth {
  double x = 0;      // visible centroid relative to ((w-1)/2, (h-1)/2)
  double y = 0;
  double area = 0;   // visible pixels
};

struct Scene {
  cv::Mat image;
  std::vector<Truth> truths;  // one per shape, in drawing order
};

// noise_sigma: standard deviation of Gaussian noise added to every channel of
// the finished frame (0 for none). Same arguments, same frame.
Scene render(cv::Size size, Background background, const std::vector<Shape>& shapes,
             double noise_sigma, std::uint64_t seed);

}  // namespace scene
