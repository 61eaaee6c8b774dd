// `tessera emulate kinect`: an RGB-D dataset (TUM RGB-D or 7-Scenes folder) as a Kinect v1
// recording in fakenect's format (drivers/fakenect_recording.hpp), so the kinect driver runs
// through libfreenect's own player as on the device (docs/architecture.md#device-drivers).
// Depth becomes raw 11-bit disparity through the Kinect's depth model: what the device sends.
// Exit codes: 0 ok; 2 usage errors; 1 a dataset that cannot be read or a recording that
// cannot be written.
#include "commands.hpp"

#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/drivers/fakenect_recording.hpp>
#include <tessera/drivers/kinect_depth.hpp>
#include <tessera/runtime/options.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <vector>

namespace tessera::app {

namespace emulate_kinect_detail {

struct KinectSettings {
  std::string rgbd, out;
  int first = 0, frames = 0;
};

struct Entry {
  double time_s;
  bool depth;
  std::size_t frame;
};

int run(const KinectSettings& s) {
  namespace drv = tessera::drivers;
  datasets::RgbdSequence seq;
  try {
    seq = datasets::readRgbdSequence(s.rgbd);
  } catch (const std::exception& e) {
    std::cerr << "emulate kinect: " << e.what() << "\n";
    return 1;
  }
  const auto n = static_cast<int>(seq.frames.size());
  if (s.first < 0 || s.first >= n)
    throw ConfigError("--first " + std::to_string(s.first) + " is outside the dataset's " +
                      std::to_string(n) + " frames");
  const int end = s.frames > 0 ? std::min(n, s.first + s.frames) : n;
  if (seq.intrinsics.width != drv::kKinectWidth || seq.intrinsics.height != drv::kKinectHeight)
    throw ConfigError("the dataset's images are " + std::to_string(seq.intrinsics.width) + " x " +
                      std::to_string(seq.intrinsics.height) + "; a Kinect's are 640 x 480");
  const double t0 = seq.frames[static_cast<std::size_t>(s.first)].timestamp;
  std::vector<Entry> entries;
  for (int i = s.first; i < end; ++i) {
    const auto& f = seq.frames[static_cast<std::size_t>(i)];
    entries.push_back({f.timestamp - t0, false, static_cast<std::size_t>(i)});
    entries.push_back({std::max(0.0, f.depth_timestamp - t0), true, static_cast<std::size_t>(i)});
  }
  std::stable_sort(entries.begin(), entries.end(),
                   [](const Entry& a, const Entry& b) { return a.time_s < b.time_s; });
  const drv::KinectDepthModel model;
  try {
    drv::FakenectRecordingWriter writer(s.out);
    std::size_t loaded = static_cast<std::size_t>(-1);
    datasets::RgbdImages images;
    std::vector<std::uint16_t> raw;
    std::size_t done = 0;
    for (const auto& e : entries) {
      if (e.frame != loaded) {
        images = datasets::loadRgbdImages(seq, e.frame);
        loaded = e.frame;
      }
      // The device's frame counter runs at 60 MHz (32 bits: it wraps every 71.6 s).
      const auto stamp = static_cast<std::uint32_t>(std::llround(e.time_s * 60e6) & 0xffffffffLL);
      if (e.depth) {
        raw.resize(images.depth.size());
        for (std::size_t k = 0; k < raw.size(); ++k)
          raw[k] = images.depth[k] == 0 ? std::uint16_t{drv::KinectDepthModel::kNoReading}
                                        : static_cast<std::uint16_t>(model.disparity(
                                              images.depth[k] / images.depth_scale));
        writer.addDepth(e.time_s, stamp, raw);
        ++done;
        if (done % 50 == 0)
          std::cerr << "emulate kinect: " << done << " / " << (end - s.first) << " frames\r"
                    << std::flush;
      } else {
        writer.addColor(e.time_s, stamp, images.color);
      }
    }
  } catch (const drv::FakenectRecordingError& e) {
    std::cerr << "emulate kinect: " << e.what() << "\n";
    return 1;
  } catch (const io::DatasetError& e) {
    std::cerr << "emulate kinect: " << e.what() << "\n";
    return 1;
  }
  std::cout << "wrote " << (end - s.first) << " Kinect frames (" << entries.back().time_s
            << " s, raw depth"
            << (seq.color_registered ? " kept registered to colour as the dataset gives it"
                                     : " in the depth camera")
            << ") to " << s.out << "\nplay them through the kinect driver: --set "
            << "camera.recording=" << s.out << " (e.g. tessera run robot_create_kinect)\n";
  return 0;
}

}  // namespace emulate_kinect_detail

void addEmulateKinectCommand(CLI::App& emulate, int& result) {
  auto k = std::make_shared<emulate_kinect_detail::KinectSettings>();
  auto* kinect = emulate.add_subcommand(
      "kinect",
      "a Kinect v1 recording (fakenect format: raw disparity + RGB) from a TUM RGB-D or "
      "7-Scenes folder, for the kinect driver");
  kinect->add_option("--rgbd", k->rgbd, "TUM RGB-D or 7-Scenes folder")
      ->required()
      ->check(CLI::ExistingDirectory);
  kinect->add_option("--out", k->out, "new folder for the recording")->required();
  kinect->add_option("--first", k->first, "first frame (default 0)");
  kinect->add_option("--frames", k->frames, "number of frames (default: all)");
  kinect->callback([k, &result] { result = emulate_kinect_detail::run(*k); });
}

}  // namespace tessera::app
