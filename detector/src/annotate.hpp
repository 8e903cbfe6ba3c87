// The picture --debug-out writes for each frame: on the left the frame with each
// chosen region outlined and its centre crossed, on the right the cleaned-up
// masks (red mask in red, blue mask in blue) with the same marks. Pure drawing.
#pragma once

#include <opencv2/core.hpp>

#include <vector>

#include "detect.hpp"

namespace detector {

// frame: the detector's last_frame(); masks: its last_masks(), one per detection.
// Returns an image twice as wide as the frame.
cv::Mat annotate(const cv::Mat& frame, const std::vector<Detection>& detections,
                 const std::vector<cv::Mat>& masks);

}  // namespace detector
