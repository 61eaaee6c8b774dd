// `tessera bench rgbd`: RGB-D visual odometry on a 7-Scenes or TUM folder. Runs our Tracker and
// OpenCV contrib's rgbd odometries (RgbdOdometry, RgbdICPOdometry, ICPOdometry, FastICPOdometry,
// frame to frame, chained) on the same frames in one run, and reports ATE RMSE after rigid
// alignment (evaluation core), ms per frame (mean, p95), keyframes and lost frames (ours: lost
// or skipped; OpenCV: frames whose compute() failed, the pose then held). Image
// decoding and 7-Scenes' depth registration are outside the timed part. For "tessera", the loop
// detector and the keyframe graph run beside the tracker on its keyframes, outside the timed part
// (rgbd_loop_eval.hpp: loops accepted and false, recall, keyframe ATE with and without loops).
#include "bench_commands.hpp"
#include "bench_util.hpp"
#include "rgbd_loop_eval.hpp"

#include <tessera/datasets/rgbd_sequence.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/visual_slam/depth_registration.hpp>
#include <tessera/visual_slam/tracker.hpp>

#include <opencv2/imgproc.hpp>
#include <opencv2/rgbd/depth.hpp>

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::app {
namespace {

namespace vs = tessera::visual_slam;

struct Options {
  std::string path = "../shared/data/7scenes-redkitchen-rgbd";
  int frames = 450;
  std::vector<std::string> methods{"tessera", "opencv_rgbd", "opencv_rgbd_icp", "opencv_icp",
                                   "opencv_fast_icp"};
  std::vector<std::string> params;  // tracker options, key=value
  bool no_registration = false;
  bool json = false;
  bool no_loops = false;
  std::string vocabulary;                // empty: bootstrapped from the first keyframes
  std::vector<std::string> loop_params;  // loop detector options, key=value
  double loop_max_error_m = 0.10, loop_max_error_deg = 5.0, revisit_overlap = 0.5;
};

struct MethodResult {
  std::string method;
  std::size_t frames = 0, keyframes = 0, lost = 0;
  std::vector<double> ms;
  double ate_rmse = 0;                   // tessera with loops: every frame moved with its keyframe
  double ate_tracker = -1;               // tessera with loops: the tracker's own poses
  vs::FrameTiming split;                 // tessera: mean per frame of each stage [ms]
  std::optional<LoopEvalFigures> loops;  // tessera with loops
};

// One frame as every method reads it: grey colour, depth in the camera the method tracks.
struct Inputs {
  cv::Mat rgb, gray, depth16, depth_m;  // depth_m: CV_32F metres, 0 -> NaN (OpenCV's odometry)
  double depth_scale = 1000, timestamp = 0;
};

class Sequence {
 public:
  Sequence(const std::string& path, int frames, bool register_depth)
      : seq_(datasets::readRgbdSequence(path)) {
    const auto& k = seq_.intrinsics;
    depth_cam_ = {k.fx, k.fy, k.cx, k.cy, k.width, k.height};
    const auto calib = vs::depthRegistration(seq_.color_registered, register_depth);
    registered_ = calib.has_value();
    calib_ =
        calib ? *calib : vs::ColorCalibration{depth_cam_, Eigen::Isometry3d::Identity(), "none"};
    count_ = std::min<std::size_t>(static_cast<std::size_t>(frames), seq_.frames.size());
  }
  std::size_t size() const { return count_; }
  const vs::PinholeCamera& depthCamera() const { return depth_cam_; }
  const vs::ColorCalibration& calibration() const { return calib_; }
  bool registered() const { return registered_; }
  std::string name() const { return seq_.folder.filename().string(); }
  /// The dataset's camera-to-world of frame i moved to the tracked (colour) camera.
  std::optional<Eigen::Isometry3d> trackedTruth(std::size_t i) const {
    const auto& p = seq_.frames.at(i).pose;
    if (!p) return std::nullopt;
    return Eigen::Isometry3d(*p * calib_.color_from_depth.inverse());
  }

  /// Frame i; `in_color`: depth registered to the colour camera (when registration applies).
  Inputs load(std::size_t i, bool in_color) const {
    auto images = datasets::loadRgbdImages(seq_, i);
    Inputs in;
    in.rgb = cv::Mat(images.height, images.width, CV_8UC3, images.color.data()).clone();
    cv::cvtColor(in.rgb, in.gray, cv::COLOR_RGB2GRAY);
    in.depth16 = cv::Mat(images.height, images.width, CV_16UC1, images.depth.data()).clone();
    if (in_color && registered_) in.depth16 = vs::registerDepth(in.depth16, depth_cam_, calib_);
    in.depth16.convertTo(in.depth_m, CV_32F, 1.0 / images.depth_scale);
    in.depth_m.setTo(std::numeric_limits<float>::quiet_NaN(), in.depth16 == 0);
    in.depth_scale = images.depth_scale;
    in.timestamp = seq_.frames[i].timestamp;
    return in;
  }

  /// ATE RMSE of depth-camera poses (one per frame, in frame order) against the dataset's.
  double ate(const std::vector<Eigen::Isometry3d>& depth_to_world) const {
    std::vector<mapping::TumPose> est, ref;
    for (std::size_t i = 0; i < depth_to_world.size(); ++i) {
      const auto stamp = static_cast<std::int64_t>(std::llround(seq_.frames[i].timestamp * 1e9));
      est.push_back({stamp, depth_to_world[i].translation(),
                     Eigen::Quaterniond(depth_to_world[i].rotation())});
      if (const auto& p = seq_.frames[i].pose)
        ref.push_back({stamp, p->translation(), Eigen::Quaterniond(p->rotation())});
    }
    return evaluation::computeAte(est, ref).translation.rmse;
  }

 private:
  datasets::RgbdSequence seq_;
  vs::PinholeCamera depth_cam_;
  vs::ColorCalibration calib_;
  bool registered_ = false;
  std::size_t count_ = 0;
};

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Options from `--param key=value` pairs, read as a profile's params block would be; a dotted
// key (verifier.ratio=0.8) names a nested group.
template <class T>
T paramOptions(const std::vector<std::string>& pairs) {
  YAML::Node node(YAML::NodeType::Map);
  for (const auto& p : pairs) {
    const auto eq = p.find('=');
    if (eq == std::string::npos || eq == 0)
      throw ConfigError("bench rgbd: --param expects key=value, got '" + p + "'");
    YAML::Node group = node;
    std::string key = p.substr(0, eq);
    for (auto dot = key.find('.'); dot != std::string::npos; dot = key.find('.')) {
      const std::string name = key.substr(0, dot);
      if (!group[name]) group[name] = YAML::Node(YAML::NodeType::Map);
      YAML::Node inner = group[name];
      group.reset(inner);  // rebinds (assignment would copy into the node)
      key = key.substr(dot + 1);
    }
    group[key] = YAML::Load(p.substr(eq + 1));
  }
  return loadOptions<T>(Params(node, "--param"));
}

MethodResult runTessera(const Sequence& s, const vs::TrackerOptions& options,
                        LoopEvaluation* loops) {
  MethodResult r;
  r.method = "tessera";
  vs::Tracker tracker(options, s.calibration().color);
  std::vector<Eigen::Isometry3d> poses;
  std::vector<std::pair<std::int64_t, Pose3>> stamped;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Inputs in = s.load(i, true);
    const auto t0 = std::chrono::steady_clock::now();
    const auto res = tracker.track({in.rgb, in.depth16, in.depth_scale, in.timestamp});
    r.ms.push_back(msSince(t0));
    const double n = static_cast<double>(s.size());
    r.split.extraction_ms += res.timing.extraction_ms / n;
    r.split.local_map_ms += res.timing.local_map_ms / n;
    r.split.matching_ms += res.timing.matching_ms / n;
    r.split.pnp_ms += res.timing.pnp_ms / n;
    r.split.local_ba_ms += res.timing.local_ba_ms / n;
    poses.push_back(res.camera_to_world * s.calibration().color_from_depth);
    stamped.emplace_back(std::llround(in.timestamp * 1e9), Pose3::fromIsometry(poses.back()));
    if (loops && res.keyframe && !tracker.keyframes().empty()) {
      const vs::Keyframe& k = tracker.keyframes().back();
      loops->addKeyframe(k, res.inliers, s.trackedTruth(k.frame));
    }
  }
  if (loops) r.loops = loops->finish();
  r.frames = s.size();
  r.keyframes = tracker.stats().keyframes;
  r.lost = tracker.stats().lost + tracker.stats().skipped;
  r.ate_rmse = s.ate(poses);
  if (r.loops && !r.loops->corrections.empty()) {
    r.ate_tracker = r.ate_rmse;
    std::vector<Eigen::Isometry3d> moved;
    for (const Pose3& p : vs::correctFramePoses(stamped, r.loops->corrections))
      moved.push_back(p.isometry());
    r.ate_rmse = s.ate(moved);
  }
  return r;
}

// OpenCV's odometry, frame to frame: Rt maps points of the previous frame into the current one.
// The colour-using ones track the colour camera (registered depth), the ICP ones the depth camera.
MethodResult runOpenCv(const Sequence& s, const std::string& method) {
  MethodResult r;
  r.method = method;
  const bool uses_color = method == "opencv_rgbd" || method == "opencv_rgbd_icp";
  const vs::PinholeCamera& cam = uses_color ? s.calibration().color : s.depthCamera();
  const Eigen::Isometry3d cam_from_depth =
      uses_color ? s.calibration().color_from_depth : Eigen::Isometry3d::Identity();
  const cv::Mat k = (cv::Mat_<float>(3, 3) << cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  cv::Ptr<cv::rgbd::Odometry> odo;
  if (method == "opencv_rgbd") odo = cv::rgbd::RgbdOdometry::create(k);
  if (method == "opencv_rgbd_icp") odo = cv::rgbd::RgbdICPOdometry::create(k);
  if (method == "opencv_icp") odo = cv::rgbd::ICPOdometry::create(k);
  if (method == "opencv_fast_icp") odo = cv::rgbd::FastICPOdometry::create(k);
  if (!odo) throw ConfigError("bench rgbd: unknown method '" + method + "'");
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  std::vector<Eigen::Isometry3d> poses;
  cv::Ptr<cv::rgbd::OdometryFrame> prev;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Inputs in = s.load(i, uses_color);
    const auto t0 = std::chrono::steady_clock::now();
    cv::Ptr<cv::rgbd::OdometryFrame> cur =
        cv::rgbd::OdometryFrame::create(uses_color ? in.gray : cv::Mat(), in.depth_m);
    odo->prepareFrameCache(cur, cv::rgbd::OdometryFrame::CACHE_ALL);
    if (prev) {
      cv::Mat rt;
      if (odo->compute(prev, cur, rt)) {
        Eigen::Matrix4d m;
        for (int a = 0; a < 4; ++a)
          for (int b = 0; b < 4; ++b) m(a, b) = rt.at<double>(a, b);
        Eigen::Isometry3d cur_from_prev(m);
        pose = pose * cur_from_prev.inverse();
      } else {
        ++r.lost;  // no motion estimate: the pose is held
      }
    }
    r.ms.push_back(msSince(t0));
    prev = cur;
    poses.push_back(pose * cam_from_depth);
  }
  r.frames = s.size();
  r.ate_rmse = s.ate(poses);
  return r;
}

void printLoops(const LoopEvalFigures& f, const Options& o) {
  std::cout << "\nloops (" << f.vocabulary << " vocabulary, outside the timed part, "
            << std::setprecision(1) << f.ms_per_keyframe << " ms per keyframe): " << f.keyframes
            << " keyframes, " << f.queries << " queries, " << f.candidates << " candidates, "
            << f.accepted << " accepted, " << f.false_loops << " false (error > "
            << std::setprecision(2) << o.loop_max_error_m << " m or " << o.loop_max_error_deg
            << " deg)";
  for (const auto& [reason, n] : f.rejected_by) std::cout << ", " << n << " " << reason;
  std::cout << "\nrecall: " << f.true_detected << " of " << f.revisits
            << " revisit keyframes (>= " << o.revisit_overlap * 100
            << " % of the points in an older keyframe's image) closed by a true loop; worst "
               "true loop error "
            << std::setprecision(3) << f.worst_true_error_m << " m\nkeyframe ATE "
            << std::setprecision(4) << f.keyframe_ate_m << " m tracker, " << f.keyframe_ate_loops_m
            << " m after the keyframe graph with the loops\n";
}

}  // namespace

void addBenchRgbdCommand(CLI::App& bench, int& result) {
  auto* cmd = bench.add_subcommand(
      "rgbd",
      "RGB-D visual odometry on a 7-Scenes or TUM folder: our tracker beside OpenCV contrib's "
      "rgbd odometries (ATE RMSE, ms per frame, keyframes, lost frames)");
  auto o = std::make_shared<Options>();
  cmd->add_option("--path", o->path, "dataset folder (7-Scenes or TUM layout)")
      ->capture_default_str();
  cmd->add_option("--frames", o->frames, "frames from the start")->capture_default_str();
  cmd->add_option("--methods", o->methods,
                  "comma-separated: tessera, opencv_rgbd, opencv_rgbd_icp, opencv_icp, "
                  "opencv_fast_icp")
      ->delimiter(',')
      ->capture_default_str();
  cmd->add_option("--param", o->params,
                  "tracker option key=value (repeatable; see the tracker's "
                  "options in docs/algorithms.md)");
  cmd->add_flag("--no-registration", o->no_registration,
                "7-Scenes: use colour as if registered to depth (sets the tracker's "
                "register_depth=false)");
  cmd->add_flag("--json", o->json, "print exactly one JSON object on stdout");
  cmd->add_flag("--no-loops", o->no_loops, "tessera: no loop detection beside the tracker");
  cmd->add_option("--vocabulary", o->vocabulary,
                  "loop detection vocabulary (DBoW2/3 YAML or ours); default: bootstrapped from "
                  "the first keyframes");
  cmd->add_option("--loop-param", o->loop_params,
                  "loop detector option key=value (repeatable; rgbd_loop_detector's detector.*)");
  cmd->add_option("--loop-max-error", o->loop_max_error_m,
                  "a loop is false beyond this translation error against the dataset [m]")
      ->capture_default_str();
  cmd->add_option("--loop-max-error-deg", o->loop_max_error_deg, "... or this rotation error [deg]")
      ->capture_default_str();
  cmd->add_option("--revisit-overlap", o->revisit_overlap,
                  "a keyframe revisits when this share of its points falls in an old keyframe")
      ->capture_default_str();
  cmd->callback([o, &result] {
    if (o->frames < 2) throw ConfigError("--frames must be >= 2");
    for (const auto& m : o->methods)
      if (m != "tessera" && m != "opencv_rgbd" && m != "opencv_rgbd_icp" && m != "opencv_icp" &&
          m != "opencv_fast_icp")
        throw ConfigError("bench rgbd: unknown method '" + m + "'");
    vs::TrackerOptions tracker_options = paramOptions<vs::TrackerOptions>(o->params);
    if (o->no_registration) tracker_options.register_depth = false;
    const auto loop_options = paramOptions<vs::LoopDetectorOptions>(o->loop_params);
    const Sequence s(o->path, o->frames, tracker_options.register_depth);
    nlohmann::json results = nlohmann::json::array();
    std::vector<MethodResult> runs;
    for (const auto& m : o->methods) {
      if (!o->json) std::cerr << "[bench rgbd] " << m << " ...\n";
      std::unique_ptr<LoopEvaluation> loops;
      if (m == "tessera" && !o->no_loops)
        loops = std::make_unique<LoopEvaluation>(loop_options, o->vocabulary, s.calibration().color,
                                                 o->loop_max_error_m, o->loop_max_error_deg,
                                                 o->revisit_overlap);
      runs.push_back(m == "tessera" ? runTessera(s, tracker_options, loops.get())
                                    : runOpenCv(s, m));
      const auto& r = runs.back();
      double mean = 0;
      for (double x : r.ms) mean += x / static_cast<double>(r.ms.size());
      results.push_back({{"method", r.method},
                         {"sequence", s.name()},
                         {"frames", r.frames},
                         {"ate_rmse_m", r.ate_rmse},
                         {"ms_per_frame_mean", mean},
                         {"ms_per_frame_p95", percentile(r.ms, 0.95)},
                         {"keyframes", r.keyframes},
                         {"loops_accepted", r.loops ? r.loops->accepted : 0},
                         {"loops_false", r.loops ? r.loops->false_loops : 0},
                         {"lost_frames", r.lost}});
    }
    if (o->json) {
      std::cout << nlohmann::json{{"machine", machineDescription()}, {"results", results}}.dump(2)
                << "\n";
      result = 0;
      return;
    }
    std::cout << "machine: " << machineDescription() << "\n"
              << "sequence: " << s.name() << ", " << s.size() << " frames; depth "
              << (s.registered() ? "registered to colour (" + s.calibration().source + ")"
                                 : std::string("as given"))
              << "\n\n"
              << std::left << std::setw(18) << "method" << std::right << std::setw(10) << "ATE m"
              << std::setw(10) << "ms mean" << std::setw(10) << "ms p95" << std::setw(11)
              << "keyframes" << std::setw(7) << "lost\n";
    for (const auto& r : results)
      std::cout << std::left << std::setw(18) << r["method"].get<std::string>() << std::right
                << std::fixed << std::setprecision(4) << std::setw(10)
                << r["ate_rmse_m"].get<double>() << std::setprecision(1) << std::setw(10)
                << r["ms_per_frame_mean"].get<double>() << std::setw(10)
                << r["ms_per_frame_p95"].get<double>() << std::setw(11)
                << r["keyframes"].get<std::size_t>() << std::setw(6)
                << r["lost_frames"].get<std::size_t>() << "\n";
    for (const auto& r : runs)
      if (r.method == "tessera")
        std::cout << "\ntessera per frame: extraction " << r.split.extraction_ms
                  << " ms, local map " << r.split.local_map_ms << " ms, matching "
                  << r.split.matching_ms << " ms, PnP " << r.split.pnp_ms << " ms, local BA "
                  << r.split.local_ba_ms << " ms; p50 " << percentile(r.ms, 0.5) << " ms\n";
    for (const auto& r : runs)
      if (r.loops) {
        printLoops(*r.loops, *o);
        if (r.ate_tracker >= 0)
          std::cout << "every frame: ATE " << std::setprecision(4) << r.ate_rmse
                    << " m moved with the optimised keyframes (the table's figure), "
                    << r.ate_tracker << " m as tracked\n";
      }
    result = 0;
  });
}

}  // namespace tessera::app
