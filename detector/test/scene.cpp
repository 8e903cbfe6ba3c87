#include "scene.hpp"

#include <opencv2/imgproc.hpp>

#include <cmath>

namespace scene {

const char* name_of(Background background) {
  switch (background) {
    case Background::plain: return "plain";
    case Background::noisy: return "noisy";
    case Background::gradient: return "gradient";
    case Background::warm_gradient: return "warm gradient";
  }
  return "?";
}

// HSV in the comments is OpenCV's 8-bit HSV (hue 0..179).
const std::vector<Paint> kReds = {
    {"red", {30, 30, 220}},           // H 0,   S 220, V 220
    {"crimson", {60, 20, 220}},       // H 174, S 232, V 220
    {"dark red", {25, 20, 170}},      // H 0,   S 225, V 170
    {"tomato", {71, 99, 255}},        // H 5,   S 184, V 255
};
const std::vector<Paint> kBlues = {
    {"blue", {200, 60, 30}},          // H 115, S 217, V 200
    {"navy-ish blue", {150, 40, 20}}, // H 115, S 221, V 150
    {"royal blue", {225, 105, 65}},   // H 113, S 181, V 225
};
const std::vector<Paint> kRedDistractors = {
    {"hot pink", {180, 105, 255}},          // H 165, S 150
    {"deep pink", {147, 20, 255}},          // H 164, S 235
    {"light pink", {193, 182, 255}},        // H 175, S 73
    {"pale violet red", {147, 112, 219}},   // H 170, S 125
    {"saddle brown", {19, 69, 139}},        // H 12,  V 139
    {"sienna", {45, 82, 160}},              // H 10,  V 160
    {"chocolate", {30, 105, 210}},          // H 12,  V 210
    {"orange", {0, 165, 255}},              // H 19
    {"dark orange", {0, 140, 255}},         // H 16
    {"deep orange", {0, 120, 255}},         // H 14
    {"dark reddish brown", {30, 40, 100}},  // H 4,   S 179, V 100
    {"maroon brown", {40, 45, 95}},         // H 3,   S 148, V 95
};
const std::vector<Paint> kBlueDistractors = {
    {"purple", {128, 0, 128}},              // H 150
    {"slate grey", {144, 128, 112}},        // H 105, S 56
};

Shape disk(cv::Point2d centre, double radius, cv::Scalar bgr) {
  return {Shape::Kind::disk, centre, {2 * radius, 2 * radius}, bgr};
}

Shape rect(cv::Point2d centre, cv::Size2d size, cv::Scalar bgr) {
  return {Shape::Kind::rect, centre, size, bgr};
}

namespace {

cv::Mat background_of(cv::Size size, Background background, cv::RNG& rng) {
  cv::Mat image(size, CV_8UC3, cv::Scalar(128, 128, 128));
  if (background == Background::gradient || background == Background::warm_gradient) {
    for (int y = 0; y < size.height; ++y) {
      const double f = static_cast<double>(y) / std::max(1, size.height - 1);
      const cv::Scalar row = background == Background::gradient
                                 ? cv::Scalar::all(30 + 200 * f)
                                 // beige (200,215,230) to brown-grey (70,90,110), S <= 90
                                 : cv::Scalar(200 - 130 * f, 215 - 125 * f, 230 - 120 * f);
      image.row(y).setTo(row);
    }
  }
  if (background == Background::noisy) {
    // Single-pixel specks of target colours: clean-up must remove them.
    const cv::Scalar specks[] = {{0, 0, 255}, {255, 0, 0}, {255, 255, 255}};
    const int count = size.area() / 300;
    for (int i = 0; i < count; ++i) {
      const cv::Point p(rng.uniform(0, size.width), rng.uniform(0, size.height));
      const cv::Scalar& s = specks[rng.uniform(0, 3)];
      image.at<cv::Vec3b>(p) = cv::Vec3b(static_cast<uchar>(s[0]), static_cast<uchar>(s[1]),
                                         static_cast<uchar>(s[2]));
    }
  }
  return image;
}

void draw_mask(cv::Mat& mask, const Shape& shape) {
  // Fixed point with 4 fractional bits, so centres need not be whole pixels.
  constexpr int shift = 4;
  constexpr double one = 1 << shift;
  if (shape.kind == Shape::Kind::disk) {
    cv::circle(mask, cv::Point(cvRound(shape.centre.x * one), cvRound(shape.centre.y * one)),
               cvRound(shape.size.width / 2 * one), cv::Scalar(255), cv::FILLED, cv::LINE_8, shift);
  } else {
    const cv::Point2d half(shape.size.width / 2, shape.size.height / 2);
    // Pixel centres inside [centre - half, centre + half).
    const cv::Point a(static_cast<int>(std::ceil(shape.centre.x - half.x - 0.5)),
                      static_cast<int>(std::ceil(shape.centre.y - half.y - 0.5)));
    const cv::Point b(static_cast<int>(std::ceil(shape.centre.x + half.x - 0.5)),
                      static_cast<int>(std::ceil(shape.centre.y + half.y - 0.5)));
    cv::rectangle(mask, cv::Rect(a, b), cv::Scalar(255), cv::FILLED);
  }
}

}  // namespace

Scene render(cv::Size size, Background background, const std::vector<Shape>& shapes,
             double noise_sigma, std::uint64_t seed) {
  cv::RNG rng(seed);
  Scene out;
  out.image = background_of(size, background, rng);
  std::vector<cv::Mat> masks;
  for (const auto& shape : shapes) {
    cv::Mat mask(size, CV_8U, cv::Scalar(0));
    draw_mask(mask, shape);
    out.image.setTo(shape.bgr, mask);
    for (auto& earlier : masks) earlier.setTo(0, mask);
    masks.push_back(mask);
  }
  for (const auto& mask : masks) {
    const cv::Moments m = cv::moments(mask, true);
    Truth t;
    t.area = m.m00;
    if (m.m00 > 0) {
      t.x = m.m10 / m.m00 - (size.width - 1) / 2.0;
      t.y = m.m01 / m.m00 - (size.height - 1) / 2.0;
    }
    out.truths.push_back(t);
  }
  if (noise_sigma > 0) {
    cv::Mat noise(size, CV_16SC3);
    rng.fill(noise, cv::RNG::NORMAL, cv::Scalar::all(0), cv::Scalar::all(noise_sigma));
    cv::Mat wide;
    out.image.convertTo(wide, CV_16SC3);
    wide += noise;
    wide.convertTo(out.image, CV_8UC3);  // saturates at 0 and 255
  }
  return out;
}

}  // namespace scene
