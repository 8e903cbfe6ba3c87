#include "detect.hpp"

#include <opencv2/imgproc.hpp>

#include <cmath>

namespace detector {
namespace {

// A size of 1 leaves the mask as it is; odd sizes keep the kernel centred, so
// erode and dilate do not shift the region (settings.cpp rejects even sizes).
cv::Mat kernel_of(int size) {
  if (size <= 1) return cv::Mat();
  return cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(size, size));
}

}  // namespace

Detector::Detector(const Settings& settings)
    : settings_(settings),
      erode_kernel_(kernel_of(settings.erode)),
      dilate_kernel_(kernel_of(settings.dilate)),
      masks_(settings.colours.size()) {}

std::vector<Detection> Detector::detect(const cv::Mat& input) {
  cv::Mat bgr = input;
  if (input.channels() == 1) {
    cv::cvtColor(input, scratch_, cv::COLOR_GRAY2BGR);
    bgr = scratch_;
  } else if (input.channels() == 4) {
    cv::cvtColor(input, scratch_, cv::COLOR_BGRA2BGR);
    bgr = scratch_;
  }
  const cv::Size want(settings_.frame_width, settings_.frame_height);
  if (want.area() > 0 && bgr.size() != want) {
    const bool shrinking = bgr.cols > want.width || bgr.rows > want.height;
    cv::resize(bgr, frame_, want, 0, 0, shrinking ? cv::INTER_AREA : cv::INTER_LINEAR);
  } else {
    bgr.copyTo(frame_);
  }
  cv::cvtColor(frame_, hsv_, cv::COLOR_BGR2HSV);

  std::vector<Detection> out;
  out.reserve(settings_.colours.size());
  for (size_t i = 0; i < settings_.colours.size(); ++i) {
    threshold(settings_.colours[i], masks_[i]);
    out.push_back(largest_region(settings_.colours[i], masks_[i]));
  }
  return out;
}

void Detector::threshold(const ColourSpec& spec, cv::Mat& mask) {
  const cv::Scalar lo(spec.hue.lo, spec.sat.lo, spec.val.lo);
  const cv::Scalar hi(spec.hue.hi, spec.sat.hi, spec.val.hi);
  if (spec.hue.lo <= spec.hue.hi) {
    cv::inRange(hsv_, lo, hi, mask);
  } else {
    // The range wraps through hue 0 (OpenCV hue runs 0..179): red is
    // [lo..179] together with [0..hi].
    cv::inRange(hsv_, lo, cv::Scalar(179, spec.sat.hi, spec.val.hi), mask);
    cv::inRange(hsv_, cv::Scalar(0, spec.sat.lo, spec.val.lo), hi, wrap_);
    cv::bitwise_or(mask, wrap_, mask);
  }
  // Erode first so isolated noise pixels vanish, then dilate to give the
  // surviving regions their size back.
  if (!erode_kernel_.empty()) cv::erode(mask, mask, erode_kernel_);
  if (!dilate_kernel_.empty()) cv::dilate(mask, mask, dilate_kernel_);
}

Detection Detector::largest_region(const ColourSpec& spec, const cv::Mat& mask) const {
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);

  Detection best;
  best.colour = spec.name;
  cv::Moments best_moments;
  for (auto& contour : contours) {
    const cv::Moments m = cv::moments(contour);
    if (m.m00 > 0 && m.m00 >= spec.min_area && m.m00 > best_moments.m00) {
      best_moments = m;
      best.outline = std::move(contour);
    }
  }
  if (best_moments.m00 <= 0) return best;

  best.found = true;
  best.centre = {best_moments.m10 / best_moments.m00, best_moments.m01 / best_moments.m00};
  best.area = std::lround(best_moments.m00);
  best.x = static_cast<int>(std::lround(best.centre.x - (mask.cols - 1) / 2.0));
  best.y = static_cast<int>(std::lround(best.centre.y - (mask.rows - 1) / 2.0));
  return best;
}

}  // namespace detector
