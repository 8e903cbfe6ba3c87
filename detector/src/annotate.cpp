#include "annotate.hpp"

#include <opencv2/imgproc.hpp>

#include <string>

namespace detector {
namespace {

// The mark colours stand out against the colour they mark.
cv::Scalar paint_of(const std::string& colour) {
  return colour == "red" ? cv::Scalar(0, 0, 230) : cv::Scalar(230, 60, 0);
}
cv::Scalar mark_of(const std::string& colour) {
  return colour == "red" ? cv::Scalar(0, 255, 0) : cv::Scalar(0, 255, 255);
}

void mark(cv::Mat& canvas, const Detection& d) {
  if (!d.found) return;
  const cv::Scalar ink = mark_of(d.colour);
  cv::polylines(canvas, std::vector<std::vector<cv::Point>>{d.outline}, true, ink, 1, cv::LINE_AA);
  const cv::Point c(cvRound(d.centre.x), cvRound(d.centre.y));
  const int arm = 6;
  cv::line(canvas, c - cv::Point(arm, 0), c + cv::Point(arm, 0), cv::Scalar(0, 0, 0), 3);
  cv::line(canvas, c - cv::Point(0, arm), c + cv::Point(0, arm), cv::Scalar(0, 0, 0), 3);
  cv::line(canvas, c - cv::Point(arm, 0), c + cv::Point(arm, 0), cv::Scalar(255, 255, 255), 1);
  cv::line(canvas, c - cv::Point(0, arm), c + cv::Point(0, arm), cv::Scalar(255, 255, 255), 1);
}

void label(cv::Mat& canvas, const Detection& d, int row) {
  const std::string text = d.found ? d.colour + " " + std::to_string(d.x) + "," +
                                         std::to_string(d.y) + " a=" + std::to_string(d.area)
                                   : d.colour + " none";
  const cv::Point at(4, 14 + 14 * row);
  cv::putText(canvas, text, at, cv::FONT_HERSHEY_PLAIN, 1.0, cv::Scalar(0, 0, 0), 3);
  cv::putText(canvas, text, at, cv::FONT_HERSHEY_PLAIN, 1.0, mark_of(d.colour), 1);
}

}  // namespace

cv::Mat annotate(const cv::Mat& frame, const std::vector<Detection>& detections,
                 const std::vector<cv::Mat>& masks) {
  cv::Mat canvas(frame.rows, frame.cols * 2, CV_8UC3, cv::Scalar(0, 0, 0));
  cv::Mat left = canvas(cv::Rect(0, 0, frame.cols, frame.rows));
  cv::Mat right = canvas(cv::Rect(frame.cols, 0, frame.cols, frame.rows));
  frame.copyTo(left);
  for (size_t i = 0; i < detections.size() && i < masks.size(); ++i) {
    if (!masks[i].empty() && masks[i].size() == frame.size())
      right.setTo(paint_of(detections[i].colour), masks[i]);
  }
  // The frame centre, the origin of x and y.
  for (cv::Mat* side : {&left, &right}) {
    const cv::Point mid(frame.cols / 2, frame.rows / 2);
    cv::drawMarker(*side, mid, cv::Scalar(128, 128, 128), cv::MARKER_CROSS, 10, 1);
  }
  for (size_t i = 0; i < detections.size(); ++i) {
    mark(left, detections[i]);
    mark(right, detections[i]);
    label(left, detections[i], static_cast<int>(i));
  }
  return canvas;
}

}  // namespace detector
