// Where frames come from: a camera (/dev/videoN or an index), a GStreamer
// pipeline (any SRC containing '!'), a video file, an image file, or a
// directory of images taken in sorted name order.
#pragma once

#include <opencv2/core.hpp>

#include <memory>
#include <string>

#include "settings.hpp"

namespace detector {

enum class SourceKind { camera, pipeline, video, image, directory };

struct Frame {
  cv::Mat image;
  std::string name;  // the image's file name; empty for camera, pipeline and video frames
};

class FrameSource {
 public:
  enum class Step { frame, end, failed };
  virtual ~FrameSource() = default;

  // Step::failed leaves a one-line message in problem().
  virtual Step next(Frame& out) = 0;
  const std::string& problem() const { return problem_; }

 protected:
  std::string problem_;
};

// Decided from the text alone, before anything is opened.
SourceKind classify_source(const std::string& spec);

struct SourceOptions {
  // A single frame (every image of a directory once). Otherwise a camera or
  // pipeline runs until its stream ends, a video plays to its end, and an image
  // or a directory is replayed in a loop.
  bool once = false;
  // libpng, GStreamer and GLib write their own diagnostics straight to stderr
  // while a source opens or an image decodes; they are hidden unless verbose,
  // so a failure reads as our one line naming the culprit.
  bool verbose = false;
};

// On failure returns null and sets problem to a message naming the source.
std::unique_ptr<FrameSource> open_source(const std::string& spec, const Settings& settings,
                                         const SourceOptions& options, std::string& problem);

}  // namespace detector
