#include "frame_source.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <system_error>
#include <vector>

namespace fs = std::filesystem;

namespace detector {
namespace {

std::string quoted(const std::string& s) { return "\"" + s + "\""; }

// Points stderr at /dev/null for its lifetime (see SourceOptions::verbose).
class QuietStderr {
 public:
  explicit QuietStderr(bool verbose) {
    if (verbose) return;
    std::fflush(stderr);
    saved_ = ::dup(2);
    const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
    if (saved_ >= 0 && null >= 0) ::dup2(null, 2);
    if (null >= 0) ::close(null);
  }
  ~QuietStderr() {
    if (saved_ < 0) return;
    std::fflush(stderr);
    ::dup2(saved_, 2);
    ::close(saved_);
  }
  QuietStderr(const QuietStderr&) = delete;
  QuietStderr& operator=(const QuietStderr&) = delete;

 private:
  int saved_ = -1;
};

cv::Mat read_image(const std::string& path, bool verbose) {
  QuietStderr quiet(verbose);
  return cv::imread(path, cv::IMREAD_COLOR);
}

bool is_image_name(const fs::path& path) {
  static const char* const extensions[] = {".png", ".jpg", ".jpeg", ".jpe", ".bmp", ".dib",
                                           ".ppm", ".pgm", ".pbm",  ".pnm", ".tif", ".tiff",
                                           ".webp"};
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return std::find(std::begin(extensions), std::end(extensions), ext) != std::end(extensions);
}

bool all_digits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

// Camera, pipeline and video: whatever cv::VideoCapture delivers.
class CaptureSource : public FrameSource {
 public:
  CaptureSource(cv::VideoCapture capture, std::string what, bool live, bool once)
      : capture_(std::move(capture)), what_(std::move(what)), live_(live), once_(once) {}

  Step next(Frame& out) override {
    if (once_ && count_ > 0) return Step::end;
    out.name.clear();
    if (!capture_.read(out.image) || out.image.empty()) {
      if (count_ == 0) {
        problem_ = what_ + " delivered no frame";
        return Step::failed;
      }
      if (live_) {
        problem_ = what_ + " stopped delivering frames";
        return Step::failed;
      }
      return Step::end;
    }
    ++count_;
    return Step::frame;
  }

 private:
  cv::VideoCapture capture_;
  std::string what_;
  bool live_;   // a camera never ends on its own: losing it is a failure
  bool once_;
  long count_ = 0;
};

// An image file or a directory's images, read from disk each time they come
// round, so a replayed directory picks up files changed in place.
class ImageSource : public FrameSource {
 public:
  ImageSource(std::vector<fs::path> paths, bool loop, bool verbose)
      : paths_(std::move(paths)), loop_(loop), verbose_(verbose) {}

  Step next(Frame& out) override {
    if (index_ == paths_.size()) {
      if (!loop_) return Step::end;
      index_ = 0;
    }
    const fs::path& path = paths_[index_++];
    out.image = read_image(path.string(), verbose_);
    out.name = path.filename().string();
    if (out.image.empty()) {
      problem_ = "cannot read image " + quoted(path.string());
      return Step::failed;
    }
    return Step::frame;
  }

 private:
  std::vector<fs::path> paths_;
  bool loop_;
  bool verbose_;
  size_t index_ = 0;
};

void ask_frame_size(cv::VideoCapture& capture, const Settings& settings) {
  if (settings.frame_width > 0) {
    capture.set(cv::CAP_PROP_FRAME_WIDTH, settings.frame_width);
    capture.set(cv::CAP_PROP_FRAME_HEIGHT, settings.frame_height);
  }
}

}  // namespace

SourceKind classify_source(const std::string& spec) {
  if (spec.find('!') != std::string::npos) return SourceKind::pipeline;
  if (all_digits(spec) || spec.rfind("/dev/video", 0) == 0) return SourceKind::camera;
  std::error_code ec;
  if (fs::is_directory(spec, ec)) return SourceKind::directory;
  if (is_image_name(spec)) return SourceKind::image;
  return SourceKind::video;
}

std::unique_ptr<FrameSource> open_source(const std::string& spec, const Settings& settings,
                                         const SourceOptions& options, std::string& problem) {
  const bool once = options.once;
  std::error_code ec;
  switch (classify_source(spec)) {
    case SourceKind::pipeline: {
      cv::VideoCapture capture;
      {
        QuietStderr quiet(options.verbose);
        capture.open(spec, cv::CAP_GSTREAMER);
      }
      if (!capture.isOpened()) {
        problem = "cannot open GStreamer pipeline " + quoted(spec);
        return nullptr;
      }
      return std::make_unique<CaptureSource>(std::move(capture), "pipeline " + quoted(spec),
                                             false, once);
    }
    case SourceKind::camera: {
      const std::string what = "camera " + spec;
      if (!all_digits(spec) && !fs::exists(spec, ec)) {
        problem = "no such camera " + spec;
        return nullptr;
      }
      cv::VideoCapture capture;
      {
        QuietStderr quiet(options.verbose);
        if (all_digits(spec))
          capture.open(std::stoi(spec), cv::CAP_V4L2);
        else
          capture.open(spec, cv::CAP_V4L2);
      }
      if (!capture.isOpened()) {
        problem = "cannot open " + what;
        return nullptr;
      }
      ask_frame_size(capture, settings);
      return std::make_unique<CaptureSource>(std::move(capture), what, true, once);
    }
    case SourceKind::directory: {
      std::vector<fs::path> paths;
      for (const auto& entry : fs::directory_iterator(spec, ec)) {
        if (entry.is_regular_file(ec) && is_image_name(entry.path())) paths.push_back(entry.path());
      }
      if (ec) {
        problem = "cannot list directory " + quoted(spec) + ": " + ec.message();
        return nullptr;
      }
      if (paths.empty()) {
        problem = "no images in directory " + quoted(spec);
        return nullptr;
      }
      std::sort(paths.begin(), paths.end(),
                [](const fs::path& a, const fs::path& b) { return a.filename() < b.filename(); });
      return std::make_unique<ImageSource>(std::move(paths), !once, options.verbose);
    }
    case SourceKind::image:
    case SourceKind::video:
      break;
  }
  if (!fs::exists(spec, ec)) {
    problem = "no such file " + quoted(spec);
    return nullptr;
  }
  if (classify_source(spec) == SourceKind::image) {
    // Read once up front so an unreadable image fails before anything is sent.
    if (read_image(spec, options.verbose).empty()) {
      problem = "cannot read image " + quoted(spec);
      return nullptr;
    }
    return std::make_unique<ImageSource>(std::vector<fs::path>{spec}, !once, options.verbose);
  }
  cv::VideoCapture capture;
  {
    QuietStderr quiet(options.verbose);
    capture.open(spec, cv::CAP_FFMPEG);
  }
  if (!capture.isOpened()) {
    problem = "cannot read video " + quoted(spec) + " (not a video, image or directory)";
    return nullptr;
  }
  return std::make_unique<CaptureSource>(std::move(capture), "video " + quoted(spec), false, once);
}

}  // namespace detector
