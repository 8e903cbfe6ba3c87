// The detector binary as users run it: on a generated directory with
// --once --print, on single images, a video, a GStreamer pipeline; sending real
// UDP to a loopback socket; and refusing bad inputs with one clear line.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>

#include "check.hpp"
#include "groups.hpp"
#include "json_line.hpp"
#include "process.hpp"
#include "scene.hpp"

namespace fs = std::filesystem;
using check::expect;
using check::text;
using process::lines_of;
using scene::Background;

namespace {

const cv::Size kFrame(320, 240);

class TempDir {
 public:
  TempDir() {
    std::string pattern = (fs::temp_directory_path() / "detector_test.XXXXXX").string();
    if (::mkdtemp(pattern.data())) path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    if (!path_.empty()) fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// What one frame should produce; nothing for a colour means "none".
struct Expected {
  std::string name;
  std::optional<scene::Truth> red;
  std::optional<scene::Truth> blue;
};

void write_file(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// Five images whose sorted order differs from the order they are made in, and a
// text file the detector must skip.
std::vector<Expected> make_image_dir(const fs::path& dir) {
  fs::create_directories(dir);
  auto save = [&](const std::string& name, const scene::Scene& sc) {
    std::vector<int> params;
    if (fs::path(name).extension() == ".jpg") params = {cv::IMWRITE_JPEG_QUALITY, 95};
    cv::imwrite((dir / name).string(), sc.image, params);
  };
  std::vector<Expected> expected;
  auto both = scene::render(kFrame, Background::noisy,
                            {scene::disk({90.5, 150.2}, 22, scene::kReds[0].bgr),
                             scene::rect({230, 80}, {44, 36}, scene::kBlues[0].bgr)},
                            6, 11);
  save("c_both.png", both);
  auto red = scene::render(kFrame, Background::gradient,
                           {scene::disk({200.3, 60.8}, 18, scene::kReds[1].bgr)}, 2, 12);
  save("a_red.png", red);
  auto none = scene::render(kFrame, Background::plain,
                            {scene::disk({100, 100}, 40, scene::kRedDistractors[7].bgr),
                             scene::disk({220, 140}, 40, scene::kRedDistractors[0].bgr)},
                            2, 13);
  save("e_none.png", none);
  auto blue = scene::render(kFrame, Background::warm_gradient,
                            {scene::disk({-5, 200}, 30, scene::kBlues[2].bgr)}, 2, 14);
  save("b_blue.png", blue);
  auto jpeg = scene::render(kFrame, Background::plain,
                            {scene::rect({160, 120}, {50, 40}, scene::kReds[0].bgr)}, 2, 15);
  save("d_red.jpg", jpeg);
  write_file(dir / "notes.txt", "not an image\n");
  return {{"a_red.png", red.truths[0], std::nullopt},
          {"b_blue.png", std::nullopt, blue.truths[0]},
          {"c_both.png", both.truths[0], both.truths[1]},
          {"d_red.jpg", jpeg.truths[0], std::nullopt},
          {"e_none.png", std::nullopt, std::nullopt}};
}

// Checks one datagram/line against what the frame should give.
void expect_datagram(const std::string& line, const std::string& colour,
                     const std::optional<scene::Truth>& truth, double tolerance,
                     const std::string& what) {
  std::string why;
  const auto d = json_line::parse(line, why);
  if (!expect(d.has_value(), what + ": parses as the datagram format: " + line + " (" + why + ")"))
    return;
  expect(d->colour == colour, what + ": colour " + colour + " in " + line);
  if (!truth) {
    expect(d->none, what + ": " + colour + " none, got " + line);
    return;
  }
  if (!expect(!d->none, what + ": " + colour + " found, got " + line)) return;
  const double error = std::hypot(d->x - truth->x, d->y - truth->y);
  expect(error <= tolerance, text(what, ": ", colour, " at (", d->x, ",", d->y, ") vs truth (",
                                  truth->x, ",", truth->y, ")"));
}

// Lines come red then blue for each frame, frames in order.
void expect_frames(const std::vector<std::string>& lines, const std::vector<Expected>& frames,
                   double tolerance, const std::string& what) {
  if (!expect(lines.size() == 2 * frames.size(),
              text(what, ": ", 2 * frames.size(), " lines expected, got ", lines.size())))
    return;
  long long last_t = -1;
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string label = what + " [" + frames[i].name + "]";
    expect_datagram(lines[2 * i], "red", frames[i].red, tolerance, label);
    expect_datagram(lines[2 * i + 1], "blue", frames[i].blue, tolerance, label);
    for (const auto& line : {lines[2 * i], lines[2 * i + 1]}) {
      std::string why;
      if (const auto d = json_line::parse(line, why); d && !d->none) {
        expect(d->t >= last_t, what + ": t never goes back");
        last_t = d->t;
      }
    }
  }
}

process::Outcome run(const std::string& binary, std::vector<std::string> args) {
  args.insert(args.begin(), binary);
  return process::run(args);
}

void expect_clean_exit(const process::Outcome& r, const std::string& what) {
  expect(r.status == 0 && r.err.empty(),
         text(what, ": exit 0 with nothing on stderr, got ", r.status, " / ", r.err));
}

// A loopback socket on a free port.
class UdpListener {
 public:
  UdpListener() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof a;
    if (::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0 &&
        ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len) == 0)
      port_ = ntohs(a.sin_port);
  }
  ~UdpListener() { ::close(fd_); }
  int port() const { return port_; }

  // Everything that arrives until the socket stays quiet for quiet_ms.
  std::vector<std::string> drain(int quiet_ms = 300) {
    std::vector<std::string> got;
    pollfd p{fd_, POLLIN, 0};
    while (::poll(&p, 1, quiet_ms) > 0) {
      char buffer[2048];
      const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
      if (n < 0) break;
      got.emplace_back(buffer, static_cast<size_t>(n));
    }
    return got;
  }

 private:
  int fd_ = -1;
  int port_ = 0;
};

}  // namespace

namespace groups {

void cli(const std::string& binary) {
  TempDir tmp;
  const fs::path dir = tmp.path() / "frames";
  const auto frames = make_image_dir(dir);

  auto r = run(binary, {"--input", dir.string(), "--once", "--print"});
  expect_clean_exit(r, "directory --once --print");
  expect_frames(lines_of(r.out), frames, 2.0, "directory --once --print");

  r = run(binary, {"--input", (dir / "c_both.png").string(), "--once", "--print"});
  expect_clean_exit(r, "image --once --print");
  expect_frames(lines_of(r.out), {frames[2]}, 2.0, "image --once --print");

  // Without --once an image is replayed; --frames stops it.
  r = run(binary, {"--input", (dir / "a_red.png").string(), "--print", "--frames", "4", "--set",
                   "input.max_fps=0"});
  expect_clean_exit(r, "image replayed");
  expect_frames(lines_of(r.out), {frames[0], frames[0], frames[0], frames[0]}, 2.0,
                "image replayed 4 times");
  // ... and a directory goes round again.
  r = run(binary, {"--input", dir.string(), "--print", "--frames", "7"});
  expect_clean_exit(r, "directory replayed");
  expect_frames(lines_of(r.out),
                {frames[0], frames[1], frames[2], frames[3], frames[4], frames[0], frames[1]}, 2.0,
                "directory replayed for 7 frames");

  // A larger frame is resized to the configured 320x240 unless told otherwise.
  const auto big = scene::render({640, 480}, Background::plain,
                                 {scene::disk({481.3, 121.7}, 40, scene::kReds[0].bgr)}, 2, 21);
  const fs::path big_path = tmp.path() / "big.png";
  cv::imwrite(big_path.string(), big.image);
  scene::Truth half = big.truths[0];
  half.x /= 2;
  half.y /= 2;
  r = run(binary, {"--input", big_path.string(), "--once", "--print"});
  expect_frames(lines_of(r.out), {{"big.png", half, std::nullopt}}, 2.0, "640x480 at 320x240");
  r = run(binary, {"--input", big_path.string(), "--once", "--print", "--frame-size", "0x0"});
  expect_frames(lines_of(r.out), {{"big.png", big.truths[0], std::nullopt}}, 2.0,
                "640x480 kept with --frame-size 0x0");

  // Settings from a file and from --set, the command line winning.
  const fs::path conf = tmp.path() / "strict.conf";
  write_file(conf, "# only large reds\nred.min_area = 5000\n");
  const std::string c_both = (dir / "c_both.png").string();
  r = run(binary, {"--input", c_both, "--once", "--print", "--config", conf.string()});
  expect_frames(lines_of(r.out), {{"c_both", std::nullopt, frames[2].blue}}, 2.0,
                "--config red.min_area 5000");
  r = run(binary, {"--input", c_both, "--once", "--print", "--config", conf.string(), "--set",
                   "red.min_area=100"});
  expect_frames(lines_of(r.out), {frames[2]}, 2.0, "--set over --config");
  r = run(binary, {"--input", c_both, "--once", "--print", "--set", "blue.min_area=5000"});
  expect_frames(lines_of(r.out), {{"c_both", frames[2].red, std::nullopt}}, 2.0,
                "--set blue.min_area 5000");

  // Debug pictures: one per frame, frame and masks side by side.
  const fs::path debug = tmp.path() / "debug" / "out";
  r = run(binary, {"--input", dir.string(), "--once", "--print", "--debug-out", debug.string()});
  expect_clean_exit(r, "--debug-out");
  std::vector<std::string> written;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(debug, ec)) written.push_back(e.path().filename());
  std::sort(written.begin(), written.end());
  expect(written == std::vector<std::string>{"000000_a_red.png", "000001_b_blue.png",
                                             "000002_c_both.png", "000003_d_red.png",
                                             "000004_e_none.png"},
         text("one debug PNG per image, got ", written.size()));
  const cv::Mat picture = cv::imread((debug / "000002_c_both.png").string());
  expect(picture.cols == 2 * kFrame.width && picture.rows == kFrame.height,
         "debug PNG is frame and masks side by side");
  if (!picture.empty()) {
    // The red mask is painted red on the right half at the red target's centre.
    const auto& t = *frames[2].red;
    const cv::Vec3b px = picture.at<cv::Vec3b>(cvRound(t.y + 119.5) + 10, cvRound(t.x + 159.5) + 320 + 10);
    expect(px[2] > 200 && px[0] < 50, "debug PNG shows the red mask");
  }

  // A video file plays to its end (MJPG in AVI: OpenCV writes it without codecs).
  const fs::path video = tmp.path() / "moving.avi";
  cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10, kFrame);
  std::vector<Expected> video_frames;
  for (int i = 0; i < 8; ++i) {
    const auto sc = scene::render(kFrame, Background::plain,
                                  {scene::disk({60.0 + 25 * i, 120}, 20, scene::kReds[0].bgr),
                                   scene::disk({260, 60.0 + 15 * i}, 16, scene::kBlues[0].bgr)},
                                  2, 30 + i);
    writer.write(sc.image);
    video_frames.push_back({text("video frame ", i), sc.truths[0], sc.truths[1]});
  }
  writer.release();
  r = run(binary, {"--input", video.string(), "--print", "--set", "input.max_fps=0"});
  expect_clean_exit(r, "video");
  expect_frames(lines_of(r.out), video_frames, 2.0, "video to its end");
  r = run(binary, {"--input", video.string(), "--print", "--once"});
  expect_frames(lines_of(r.out), {video_frames[0]}, 2.0, "video --once");

  // A GStreamer pipeline: any SRC with '!'.
  const std::string pipeline = "multifilesrc location=" + c_both +
                               " num-buffers=3 caps=image/png,framerate=30/1 ! pngdec ! "
                               "videoconvert ! video/x-raw,format=BGR ! appsink";
  r = run(binary, {"--input", pipeline, "--print"});
  expect_clean_exit(r, "GStreamer pipeline");
  expect_frames(lines_of(r.out), {frames[2], frames[2], frames[2]}, 2.0, "GStreamer pipeline");

  r = run(binary, {"--help"});
  expect(r.status == 0 && r.out.find("--input SRC") != std::string::npos, "--help prints usage");
  r = run(binary, {"--show-config", "--set", "red.min_area=321"});
  expect(r.status == 0 && r.out.find("red.min_area = 321\n") != std::string::npos &&
             r.out.find("red.hue = 170..7\n") != std::string::npos,
         "--show-config prints the effective settings");
}

void udp(const std::string& binary) {
  TempDir tmp;
  const fs::path dir = tmp.path() / "frames";
  const auto frames = make_image_dir(dir);

  for (const std::string host : {"127.0.0.1", "", "localhost"}) {
    UdpListener listener;
    if (!expect(listener.port() > 0, "loopback socket bound")) return;
    const std::string dest = host + ":" + std::to_string(listener.port());
    const auto r = run(binary, {"--input", dir.string(), "--once", "--udp", dest});
    expect_clean_exit(r, "--udp " + dest);
    expect(r.out.empty(), "--udp alone prints nothing");
    const auto datagrams = listener.drain();
    for (const auto& d : datagrams)
      expect(d.find('\n') == std::string::npos, "one JSON object per datagram, no newline");
    expect_frames(datagrams, frames, 2.0, "datagrams to " + dest);
  }

  // --print and --udp together carry the same text.
  UdpListener listener;
  const auto r = run(binary, {"--input", dir.string(), "--once", "--print", "--udp",
                              "127.0.0.1:" + std::to_string(listener.port())});
  expect_clean_exit(r, "--print with --udp");
  expect(listener.drain() == lines_of(r.out), "datagrams equal the printed lines");

  // Nobody listening: still runs to the end.
  int port = 0;
  {
    UdpListener closed;
    port = closed.port();
  }
  const auto unheard = run(binary, {"--input", dir.string(), "--once", "--udp",
                                    "127.0.0.1:" + std::to_string(port)});
  expect(unheard.status == 0, "no listener on the port: the detector carries on");
}

void bad_inputs(const std::string& binary) {
  TempDir tmp;
  const fs::path dir = tmp.path();
  const auto good = scene::render(kFrame, Background::plain,
                                  {scene::disk({100, 100}, 20, scene::kReds[0].bgr)}, 2, 40);
  const fs::path good_png = dir / "good.png";
  cv::imwrite(good_png.string(), good.image);
  std::vector<uchar> png;
  cv::imencode(".png", good.image, png);
  write_file(dir / "garbage.png", "this is not a PNG at all");
  write_file(dir / "truncated.png", std::string(png.begin(), png.begin() + png.size() / 2));
  write_file(dir / "notes.txt", "plain text\n");
  fs::create_directories(dir / "empty");
  fs::create_directories(dir / "mixed");
  fs::copy_file(good_png, dir / "mixed" / "a.png");
  write_file(dir / "mixed" / "b.png", "broken");
  write_file(dir / "bad_value.conf", "red.min_area = 200\nred.sat = 300..10\n");
  write_file(dir / "bad_key.conf", "red.hue = 170..7\nred.colour = 3\n");
  write_file(dir / "no_equals.conf", "red.hue 170..7\n");
  const std::string image = good_png.string();

  struct Case {
    std::vector<std::string> args;
    std::string culprit;
    bool may_print = false;  // a directory fails only when it reaches the broken image
  };
  const std::vector<Case> cases = {
      {{"--input", (dir / "missing.png").string(), "--once", "--print"}, "missing.png"},
      {{"--input", (dir / "missing.avi").string(), "--print"}, "no such file"},
      {{"--input", (dir / "garbage.png").string(), "--once", "--print"}, "garbage.png"},
      {{"--input", (dir / "truncated.png").string(), "--once", "--print"}, "truncated.png"},
      {{"--input", (dir / "notes.txt").string(), "--once", "--print"}, "notes.txt"},
      {{"--input", (dir / "empty").string(), "--once", "--print"}, "no images in directory"},
      {{"--input", (dir / "mixed").string(), "--once", "--print"}, "b.png", true},
      {{"--input", "57", "--once", "--print"}, "camera 57"},
      {{"--input", "/dev/video57", "--once", "--print"}, "/dev/video57"},
      {{"--input", "nosuchelement ! appsink", "--once", "--print"}, "pipeline"},
      {{"--input", image, "--print", "--config", (dir / "bad_value.conf").string()},
       "bad_value.conf:2: red.sat"},
      {{"--input", image, "--print", "--config", (dir / "bad_key.conf").string()}, "red.colour"},
      {{"--input", image, "--print", "--config", (dir / "no_equals.conf").string()},
       "no_equals.conf:1"},
      {{"--input", image, "--print", "--config", (dir / "missing.conf").string()}, "missing.conf"},
      {{"--input", image, "--print", "--set", "red.min_area=big"}, "red.min_area"},
      {{"--input", image, "--print", "--set", "morph.erode=4"}, "morph.erode"},
      {{"--input", image, "--frame-size", "10x10"}, "--frame-size 10x10"},
      {{"--input", image, "--udp", "nohost"}, "--udp"},
      {{"--input", image, "--udp", "127.0.0.1:99999"}, "127.0.0.1:99999"},
      {{"--input", image, "--udp", ":0"}, "--udp"},
      {{"--input", image, "--udp", "robot:abc"}, "robot:abc"},
      {{"--input", image, "--udp", "no-such-host.invalid:5005"}, "no-such-host.invalid"},
      {{"--input", image, "--debug-out", image}, "--debug-out"},
      {{"--input", image, "--bogus"}, "--bogus"},
      {{"--print"}, "--input"},
  };
  for (const auto& c : cases) {
    std::string shown;
    for (const auto& a : c.args) shown += " " + a;
    const auto r = run(binary, c.args);
    const std::string what = "detector" + shown;
    expect(r.status != 0 && r.status != -1, text(what, ": exits non-zero, got ", r.status));
    const auto err = lines_of(r.err);
    expect(err.size() == 1 && r.err.back() == '\n',
           text(what, ": exactly one line on stderr, got ", err.size(), ": ", r.err));
    expect(r.err.rfind("detector: ", 0) == 0 && r.err.find(c.culprit) != std::string::npos,
           what + ": message names " + c.culprit + ", got: " + r.err);
    if (!c.may_print) expect(r.out.empty(), what + ": nothing on stdout, got: " + r.out);
  }
}

}  // namespace groups
