// The detection core: one BGR frame in, the largest red and the largest blue
// region out. Pure computation (no files, sockets or clocks), so the tests and
// the benchmark drive it directly; main.cpp is the I/O shell around it.
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

#include "settings.hpp"

namespace detector {

// One colour's verdict for one frame. x, y are integer pixels relative to the
// frame centre, the point ((width-1)/2, (height-1)/2) when pixel centres sit on
// integer coordinates, rounded half away from zero; x grows right, y grows down.
// A region symmetric about the middle of the frame is at (0, 0).
struct Detection {
  std::string colour;            // "red" or "blue"
  bool found = false;
  int x = 0;
  int y = 0;
  long area = 0;                 // px², the region outline's area (moment m00)
  cv::Point2d centre;            // unrounded, in frame pixel coordinates
  std::vector<cv::Point> outline;
};

class Detector {
 public:
  explicit Detector(const Settings& settings);

  // Detections in the order of settings.colours, one per colour, always.
  // Frames whose size differs from the configured frame size are resized first,
  // so coordinates and areas are always in the configured frame's pixels.
  std::vector<Detection> detect(const cv::Mat& frame);

  // What the last detect() saw, for the debug images: the frame after resizing
  // and each colour's cleaned-up mask.
  const cv::Mat& last_frame() const { return frame_; }
  const std::vector<cv::Mat>& last_masks() const { return masks_; }

 private:
  void threshold(const ColourSpec& spec, cv::Mat& mask);
  Detection largest_region(const ColourSpec& spec, const cv::Mat& mask) const;

  Settings settings_;
  cv::Mat erode_kernel_;
  cv::Mat dilate_kernel_;
  cv::Mat frame_;
  cv::Mat hsv_;
  cv::Mat wrap_;
  cv::Mat scratch_;
  std::vector<cv::Mat> masks_;
};

}  // namespace detector
