// The detector program: reads frames from a source, runs the detection core on
// each, and reports every colour of every frame by UDP and/or on stdout.
// Exit status: 0 done (end of input, --once, --frames or SIGINT/SIGTERM);
// 1 the input failed (missing, unreadable, camera lost) or output could not be
// written; 2 the command line or the settings are wrong.
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "annotate.hpp"
#include "datagram.hpp"
#include "detect.hpp"
#include "frame_source.hpp"
#include "options.hpp"
#include "udp_sender.hpp"

namespace fs = std::filesystem;
using detector::Problem;
using Clock = std::chrono::steady_clock;

namespace {

std::atomic<bool> stop_requested{false};

void request_stop(int) { stop_requested = true; }

int fail(int status, const std::string& message) {
  std::cerr << "detector: " << message << std::endl;
  return status;
}

Problem read_file(const std::string& path, std::string& out) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return "--config \"" + path + "\": no such file";
  if (fs::is_directory(path, ec)) return "--config \"" + path + "\": is a directory";
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  if (!in) return "--config \"" + path + "\": cannot read";
  out = text.str();
  return std::nullopt;
}

Problem prepare_debug_dir(const std::string& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (!fs::is_directory(dir, ec)) return "--debug-out \"" + dir + "\": cannot create directory";
  return std::nullopt;
}

std::string debug_name(const std::string& dir, long index, const std::string& image_name) {
  std::string name = std::to_string(index);
  if (name.size() < 6) name.insert(0, 6 - name.size(), '0');
  if (!image_name.empty()) name += "_" + fs::path(image_name).stem().string();
  return (fs::path(dir) / (name + ".png")).string();
}

}  // namespace

int main(int argc, char** argv) {
  const auto started = Clock::now();
  detector::Options options;
  const auto parsed = detector::parse_options({argv + 1, argv + argc}, options);
  // OpenCV's own warnings would turn our one-line errors into several lines.
  if (!options.verbose) cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  if (parsed) return fail(2, *parsed);
  if (options.help) {
    std::cout << detector::kUsage;
    return 0;
  }
  std::string config_text;
  if (!options.config_path.empty()) {
    if (auto problem = read_file(options.config_path, config_text)) return fail(2, *problem);
  }
  detector::Settings settings;
  if (auto problem = detector::build_settings(options, config_text, settings))
    return fail(2, *problem);
  if (options.show_config) {
    std::cout << detector::to_config_text(settings);
    return 0;
  }

  detector::UdpSender udp;
  if (options.udp) {
    if (auto problem = udp.open(*options.udp)) return fail(2, *problem);
  }
  if (!options.debug_out.empty()) {
    if (auto problem = prepare_debug_dir(options.debug_out)) return fail(2, *problem);
  }
  std::string source_problem;
  auto source = detector::open_source(options.input, settings, {options.once, options.verbose},
                                      source_problem);
  if (!source) return fail(1, "--input: " + source_problem);

  std::signal(SIGINT, request_stop);
  std::signal(SIGTERM, request_stop);

  detector::Detector detector(settings);
  const bool paced = !options.once && settings.max_fps > 0;
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(paced ? 1.0 / settings.max_fps : 0.0));
  auto due = Clock::now();
  detector::Frame frame;
  for (long index = 0; !stop_requested && (options.frames == 0 || index < options.frames); ++index) {
    if (paced) {
      std::this_thread::sleep_until(due);
      due = std::max(due + period, Clock::now());
    }
    const auto step = source->next(frame);
    if (step == detector::FrameSource::Step::end) break;
    if (step == detector::FrameSource::Step::failed) return fail(1, "--input: " + source->problem());
    const long long t_ms =
        std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - started).count();

    const auto detections = detector.detect(frame.image);
    std::string lines;
    for (const auto& d : detections) {
      const std::string payload = detector::datagram(d, t_ms);
      if (options.udp) {
        if (auto problem = udp.send(payload)) std::cerr << "detector: warning: " << *problem << "\n";
      }
      lines += payload + "\n";
    }
    if (options.print) {
      std::fwrite(lines.data(), 1, lines.size(), stdout);
      std::fflush(stdout);
    }
    if (!options.debug_out.empty()) {
      const std::string path = debug_name(options.debug_out, index, frame.name);
      const cv::Mat picture =
          detector::annotate(detector.last_frame(), detections, detector.last_masks());
      if (!cv::imwrite(path, picture)) return fail(1, "--debug-out: cannot write \"" + path + "\"");
    }
  }
  return 0;
}
