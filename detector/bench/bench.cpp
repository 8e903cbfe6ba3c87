// Detector throughput, not a test: frames per second of the detection core
// (resize if any, HSV, thresholds, clean-up, contours, moments, datagram text)
// on generated frames, single-threaded, printed as a Markdown table.
//   detector_bench [--seconds S]      (default 3 seconds per row)
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "datagram.hpp"
#include "detect.hpp"
#include "scene.hpp"

namespace {

using Clock = std::chrono::steady_clock;

// A mix like a camera's: targets of several sizes, a distractor, noise.
std::vector<cv::Mat> frames_of(cv::Size size) {
  const double k = size.width / 320.0;
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 16; ++i) {
    const cv::Point2d red(k * (40 + 15 * i), k * (60 + 7 * i));
    const cv::Point2d blue(k * (280 - 12 * i), k * (180 - 5 * i));
    std::vector<scene::Shape> shapes = {
        scene::disk(red, k * (10 + i), scene::kReds[i % scene::kReds.size()].bgr),
        scene::rect(blue, {k * 40, k * 30}, scene::kBlues[i % scene::kBlues.size()].bgr),
        scene::disk({k * 160, k * 200}, k * 25,
                    scene::kRedDistractors[i % scene::kRedDistractors.size()].bgr)};
    frames.push_back(scene::render(size, scene::Background::noisy, shapes, 6, 100 + i).image);
  }
  return frames;
}

struct Row {
  std::string label;
  long frames;
  double seconds;
};

Row measure(const std::string& label, cv::Size in, cv::Size configured, double seconds) {
  detector::Settings settings = detector::default_settings();
  settings.frame_width = configured.width;
  settings.frame_height = configured.height;
  detector::Detector detector(settings);
  const auto frames = frames_of(in);
  std::size_t bytes = 0;
  for (const auto& f : frames) detector.detect(f);  // warm-up: allocations, caches
  long count = 0;
  const auto start = Clock::now();
  const auto stop = start + std::chrono::duration<double>(seconds);
  while (Clock::now() < stop) {
    for (const auto& d : detector.detect(frames[count % frames.size()]))
      bytes += detector::datagram(d, count).size();
    ++count;
  }
  const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
  if (bytes == 0) std::abort();  // keeps the formatting from being optimised away
  return {label, count, elapsed};
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 3;
  if (argc == 3 && std::string(argv[1]) == "--seconds") seconds = std::atof(argv[2]);
  if (seconds <= 0) {
    std::fprintf(stderr, "usage: detector_bench [--seconds S]\n");
    return 2;
  }
  cv::setNumThreads(1);
  const std::vector<Row> rows = {
      measure("320x240", {320, 240}, {320, 240}, seconds),
      measure("640x480", {640, 480}, {640, 480}, seconds),
      measure("640x480 resized to 320x240", {640, 480}, {320, 240}, seconds),
  };
  std::printf("| frame | frames | fps | ms/frame |\n|---|---:|---:|---:|\n");
  for (const auto& r : rows)
    std::printf("| %s | %ld | %.0f | %.2f |\n", r.label.c_str(), r.frames, r.frames / r.seconds,
                1000 * r.seconds / r.frames);
  std::printf("\nsingle-threaded (cv::setNumThreads(1)), OpenCV %s, %.1f s per row\n",
              CV_VERSION, seconds);
  return 0;
}
