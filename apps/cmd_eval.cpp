// `tessera eval relations|ate|rpe|landmarks|loops`: accuracy of a trajectory or landmark map
// against a reference. Without --json the summary goes to stdout; with --json stdout holds exactly
// one JSON object and the summary goes to stderr, so the output can be piped into other tools. Exit
// codes: 0 ok; 2 usage errors (bad option values, an input file that does not exist); 1 bad input
// contents (malformed line: the message names file:line) or nothing to compare.
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/datasets/relations.hpp>
#include <tessera/evaluation/landmark_io.hpp>
#include <tessera/evaluation/loop_metrics.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
#include <tessera/runtime/options.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>

namespace tessera::app {

namespace fs = std::filesystem;
using namespace tessera::evaluation;
using namespace tessera::mapping;

namespace {

void requireFinite(double v, const char* option) {
  if (!std::isfinite(v)) throw ConfigError(std::string(option) + " must be a finite number");
}

std::vector<TumPose> loadTrajectory(const std::string& path, const char* option) {
  requireFile(path, option);
  auto poses = readTum(path);
  if (poses.empty()) throw TrajectoryError(path + ": no poses in the file");
  return poses;
}

/// One aligned line of the human summary: label, value, unit.
class Summary {
 public:
  explicit Summary(std::string title) { out_ << title << "\n"; }
  void row(const std::string& label, const std::string& value, const std::string& unit = "") {
    // Pad by characters, not bytes: labels such as "rotation²" hold multi-byte UTF-8.
    std::size_t width = 0;
    for (unsigned char c : label) width += (c & 0xC0) != 0x80;
    out_ << "  " << label << std::string(width < 18 ? 18 - width : 1, ' ') << value;
    if (!unit.empty()) out_ << " " << unit;
    out_ << "\n";
  }
  void stats(const std::string& label, const ErrorStats& s, const std::string& unit, int digits) {
    row(label + " [" + unit + "]", "rmse " + num(s.rmse, digits) + "   mean " +
                                       num(s.mean, digits) + "   median " + num(s.median, digits) +
                                       "   max " + num(s.max, digits));
  }
  void meanStd(const std::string& label, const ErrorStats& s, const std::string& unit, int digits) {
    row(label, num(s.mean, digits) + " ± " + num(s.std, digits), unit);
  }
  static std::string num(double v, int digits) {
    std::ostringstream o;
    o << std::fixed << std::setprecision(digits) << v;
    return o.str();
  }
  void print(bool json) const { (json ? std::cerr : std::cout) << out_.str(); }

 private:
  std::ostringstream out_;
};

std::string modeName(bool planar) {
  return planar ? "SE(2)" : "SE(3)";
}

Dimension dimensionOf(bool planar, bool spatial) {
  return planar ? Dimension::kPlanar : spatial ? Dimension::kSpatial : Dimension::kAuto;
}

void addRelations(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "relations", "Kümmerle et al. 2009 relations metric of a trajectory (TUM file)");
  struct Args {
    std::string trajectory, relations;
    double max_gap_s = RelationsOptions{}.max_gap_s;
    double time_offset_s = 0;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--trajectory", a->trajectory, "estimated trajectory, TUM format")->required();
  cmd->add_option("--relations", a->relations, "relations file 't1 t2 dx dy dz roll pitch yaw'")
      ->required();
  cmd->add_option("--max-gap", a->max_gap_s,
                  "[s] relation times between trajectory poses further apart are not matched "
                  "(0: no limit)")
      ->capture_default_str();
  cmd->add_option("--time-offset", a->time_offset_s,
                  "[s] added to the trajectory stamps to bring them to the relations' time base")
      ->capture_default_str();
  cmd->add_flag("--json", a->json, "print one JSON object on stdout");
  cmd->callback([a, &result] {
    if (!(a->max_gap_s >= 0)) throw ConfigError("--max-gap must be a number >= 0");
    requireFinite(a->time_offset_s, "--time-offset");
    const auto trajectory = loadTrajectory(a->trajectory, "--trajectory");
    const std::vector<PoseRelation> relations = loadPoseRelations(a->relations, "--relations");
    RelationsOptions options;
    options.max_gap_s = a->max_gap_s;
    options.time_offset_s = a->time_offset_s;
    const RelationsResult r = computeRelationsError(trajectory, relations, options);

    Summary s("relations metric (Kümmerle et al. 2009)");
    s.row("trajectory", a->trajectory + " (" + std::to_string(trajectory.size()) + " poses)");
    s.row("relations", a->relations + " (" + std::to_string(r.relations) + ")");
    s.row("matched", std::to_string(r.matched) + " of " + std::to_string(r.relations) + " (" +
                         std::to_string(r.outside) + " outside the trajectory, " +
                         std::to_string(r.in_gap) + " in gaps > " + Summary::num(a->max_gap_s, 1) +
                         " s)");
    s.meanStd("translation", r.translation, "m", 4);
    s.meanStd("translation²", r.translation_squared, "m²", 4);
    s.meanStd("rotation", r.rotation_deg, "deg", 3);
    s.meanStd("rotation²", r.rotation_squared_deg, "deg²", 3);
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["relations"] = r.relations;
      j["matched"] = r.matched;
      j["outside"] = r.outside;
      j["in_gap"] = r.in_gap;
      j["trans_mean_m"] = r.translation.mean;
      j["trans_std_m"] = r.translation.std;
      j["trans2_mean"] = r.translation_squared.mean;
      j["trans2_std"] = r.translation_squared.std;
      j["rot_mean_deg"] = r.rotation_deg.mean;
      j["rot_std_deg"] = r.rotation_deg.std;
      j["rot2_mean"] = r.rotation_squared_deg.mean;
      j["rot2_std"] = r.rotation_squared_deg.std;
      std::cout << j.dump(2) << "\n";
    }
    result = 0;
  });
}

struct PairArgs {
  std::string estimate, reference;
  double offset_s = 0;
  bool planar = false, spatial = false, json = false;
};

/// --estimate, --reference, --offset, --json and, with `dimension`, --2d / --3d.
void addPairOptions(CLI::App* cmd, PairArgs& a, bool dimension = true) {
  cmd->add_option("--estimate", a.estimate, "estimated trajectory, TUM format")->required();
  cmd->add_option("--reference", a.reference, "reference (ground truth) trajectory, TUM format")
      ->required();
  cmd->add_option("--offset", a.offset_s, "[s] added to the estimate stamps")
      ->capture_default_str();
  if (dimension) {
    auto* p =
        cmd->add_flag("--2d", a.planar, "SE(2): compare in the xy plane (default: automatic)");
    auto* s = cmd->add_flag("--3d", a.spatial, "SE(3) even for planar files");
    p->excludes(s);
  }
  cmd->add_flag("--json", a.json, "print one JSON object on stdout");
}

void addAte(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "ate", "absolute trajectory error after rigid alignment (TUM RGB-D conventions)");
  struct Args : PairArgs {
    double max_diff_s = AssociationOptions{}.max_difference_s;
    bool scale = false;
  };
  auto a = std::make_shared<Args>();
  addPairOptions(cmd, *a);
  cmd->add_option("--max-diff", a->max_diff_s, "[s] largest stamp difference of a pose pair")
      ->capture_default_str();
  cmd->add_flag("--scale", a->scale, "also estimate a scale (monocular estimates)");
  cmd->callback([a, &result] {
    if (!(a->max_diff_s >= 0)) throw ConfigError("--max-diff must be a number >= 0");
    requireFinite(a->offset_s, "--offset");
    const auto estimate = loadTrajectory(a->estimate, "--estimate");
    const auto reference = loadTrajectory(a->reference, "--reference");
    AteOptions options;
    options.association.max_difference_s = a->max_diff_s;
    options.association.offset_s = a->offset_s;
    options.dimension = dimensionOf(a->planar, a->spatial);
    options.scale = a->scale;
    const AteResult r = computeAte(estimate, reference, options);

    Summary s("absolute trajectory error (ATE)");
    s.row("estimate", a->estimate + " (" + std::to_string(r.estimate_poses) + " poses)");
    s.row("reference", a->reference + " (" + std::to_string(r.reference_poses) + " poses)");
    s.row("pairs", std::to_string(r.pairs) + " (|Δt| ≤ " + Summary::num(a->max_diff_s, 3) + " s)");
    s.row("alignment",
          modeName(r.planar) + (a->scale ? " + scale " + Summary::num(r.alignment.scale, 4) : ""));
    s.stats("translation", r.translation, "m", 4);
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["pairs"] = r.pairs;
      j["rmse_m"] = r.translation.rmse;
      j["mean_m"] = r.translation.mean;
      j["median_m"] = r.translation.median;
      j["max_m"] = r.translation.max;
      j["std_m"] = r.translation.std;
      j["min_m"] = r.translation.min;
      j["mode"] = r.planar ? "se2" : "se3";
      j["scale"] = r.alignment.scale;
      j["estimate_poses"] = r.estimate_poses;
      j["reference_poses"] = r.reference_poses;
      std::cout << j.dump(2) << "\n";
    }
    result = 0;
  });
}

void addRpe(CLI::App& eval, int& result) {
  auto* cmd =
      eval.add_subcommand("rpe", "relative pose error over a fixed delta (TUM RGB-D conventions)");
  struct Args : PairArgs {
    double delta = 1.0;
    std::string unit = "s";
  };
  auto a = std::make_shared<Args>();
  addPairOptions(cmd, *a);
  cmd->add_option("--delta", a->delta, "pair spacing, in --delta-unit")->capture_default_str();
  cmd->add_option("--delta-unit", a->unit, "s (seconds) or f (frames of the estimate)")
      ->check(CLI::IsMember({"s", "f"}))
      ->capture_default_str();
  cmd->callback([a, &result] {
    RpeOptions options;
    options.unit = a->unit == "f" ? DeltaUnit::kFrames : DeltaUnit::kSeconds;
    if (!(a->delta > 0) || !std::isfinite(a->delta))
      throw ConfigError("--delta must be a positive number");
    requireFinite(a->offset_s, "--offset");
    if (options.unit == DeltaUnit::kFrames && a->delta != std::floor(a->delta))
      throw ConfigError("--delta in frames must be a whole number");
    const auto estimate = loadTrajectory(a->estimate, "--estimate");
    const auto reference = loadTrajectory(a->reference, "--reference");
    options.delta = a->delta;
    options.offset_s = a->offset_s;
    options.dimension = dimensionOf(a->planar, a->spatial);
    const RpeResult r = computeRpe(estimate, reference, options);

    Summary s("relative pose error (RPE)");
    s.row("estimate", a->estimate + " (" + std::to_string(r.estimate_poses) + " poses)");
    s.row("reference", a->reference + " (" + std::to_string(r.reference_poses) + " poses)");
    s.row("pairs", std::to_string(r.pairs) + " (delta " + Summary::num(a->delta, 3) +
                       (options.unit == DeltaUnit::kFrames ? " frames" : " s") + ", " +
                       modeName(r.planar) + ")");
    s.stats("translation", r.translation, "m", 4);
    s.stats("rotation", r.rotation_deg, "deg", 3);
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["pairs"] = r.pairs;
      j["rmse_m"] = r.translation.rmse;
      j["mean_m"] = r.translation.mean;
      j["median_m"] = r.translation.median;
      j["max_m"] = r.translation.max;
      j["rot_rmse_deg"] = r.rotation_deg.rmse;
      j["rot_mean_deg"] = r.rotation_deg.mean;
      j["rot_median_deg"] = r.rotation_deg.median;
      j["rot_max_deg"] = r.rotation_deg.max;
      j["delta"] = a->delta;
      j["delta_unit"] = a->unit;
      j["mode"] = r.planar ? "se2" : "se3";
      std::cout << j.dump(2) << "\n";
    }
    result = 0;
  });
}

void addHeading(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "heading", "heading drift of odometry: heading error since the first pose, unaligned");
  struct Args : PairArgs {
    double max_diff_s = AssociationOptions{}.max_difference_s;
  };
  auto a = std::make_shared<Args>();
  addPairOptions(cmd, *a, /*dimension=*/false);  // headings are planar
  cmd->add_option("--max-diff", a->max_diff_s, "[s] largest stamp difference of a pose pair")
      ->capture_default_str();
  cmd->callback([a, &result] {
    if (!(a->max_diff_s >= 0)) throw ConfigError("--max-diff must be a number >= 0");
    requireFinite(a->offset_s, "--offset");
    const auto estimate = loadTrajectory(a->estimate, "--estimate");
    const auto reference = loadTrajectory(a->reference, "--reference");
    AssociationOptions options;
    options.max_difference_s = a->max_diff_s;
    options.offset_s = a->offset_s;
    const HeadingDriftResult r = computeHeadingDrift(estimate, reference, options);

    Summary s("heading drift (since the first pose, unaligned)");
    s.row("estimate", a->estimate + " (" + std::to_string(r.estimate_poses) + " poses)");
    s.row("reference", a->reference + " (" + std::to_string(r.reference_poses) + " poses)");
    s.row("pairs", std::to_string(r.pairs) + " over " + Summary::num(r.duration_s, 1) + " s");
    s.row("final", Summary::num(r.final_signed_deg, 3) + " deg");
    s.stats("heading error", r.error_deg, "deg", 3);
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["pairs"] = r.pairs;
      j["duration_s"] = r.duration_s;
      j["final_deg"] = r.final_deg;
      j["final_signed_deg"] = r.final_signed_deg;
      j["rmse_deg"] = r.error_deg.rmse;
      j["mean_deg"] = r.error_deg.mean;
      j["max_deg"] = r.error_deg.max;
      std::cout << j.dump(2) << "\n";
    }
    result = 0;
  });
}

void addLandmarks(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "landmarks", "landmark map error after rigid 2D alignment (files of 'id x y' lines)");
  struct Args {
    std::string estimate, reference;
    bool scale = false, json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--estimate", a->estimate, "estimated landmarks, 'id x y' per line")->required();
  cmd->add_option("--reference", a->reference, "reference landmarks, same format")->required();
  cmd->add_flag("--scale", a->scale, "also estimate a scale");
  cmd->add_flag("--json", a->json, "print one JSON object on stdout");
  cmd->callback([a, &result] {
    requireFile(a->estimate, "--estimate");
    requireFile(a->reference, "--reference");
    const auto estimate = readLandmarks(a->estimate);
    const auto reference = readLandmarks(a->reference);
    const LandmarkResult r = computeLandmarkError(estimate, reference, a->scale);

    Summary s("landmark map error");
    s.row("estimate", a->estimate + " (" + std::to_string(r.estimate_landmarks) + " landmarks)");
    s.row("reference", a->reference + " (" + std::to_string(r.reference_landmarks) + " landmarks)");
    s.row("pairs", std::to_string(r.pairs) + " (same id)");
    s.stats("position", r.error, "m", 4);
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["pairs"] = r.pairs;
      j["rmse_m"] = r.error.rmse;
      j["mean_m"] = r.error.mean;
      j["median_m"] = r.error.median;
      j["max_m"] = r.error.max;
      j["estimate_landmarks"] = r.estimate_landmarks;
      j["reference_landmarks"] = r.reference_landmarks;
      j["scale"] = r.alignment.scale;
      std::cout << j.dump(2) << "\n";
    }
    result = 0;
  });
}

void addLoops(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "loops", "loop closures of a keyframe graph against a reference trajectory (precision)");
  struct Args {
    std::string graph, keyframes, reference;
    LoopCheckOptions check;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--graph", a->graph, "keyframe graph, g2o (keyframe_graph.g2o)")->required();
  cmd->add_option("--keyframes", a->keyframes,
                  "the graph's keyframes in id order, TUM (keyframes.tum): their stamps")
      ->required();
  cmd->add_option("--reference", a->reference, "reference trajectory, TUM (ground_truth.tum)")
      ->required();
  cmd->add_option("--max-error", a->check.max_error_m, "[m] a loop further off is false")
      ->capture_default_str();
  cmd->add_option("--max-error-deg", a->check.max_error_deg, "[deg] a loop further off is false")
      ->capture_default_str();
  cmd->add_option("--max-diff", a->check.max_difference_s,
                  "[s] largest stamp difference to a reference pose")
      ->capture_default_str();
  cmd->add_flag("--json", a->json, "print one JSON object on stdout");
  cmd->callback([a, &result] {
    requireFinite(a->check.max_error_m, "--max-error");
    requireFinite(a->check.max_error_deg, "--max-error-deg");
    requireFile(a->graph, "--graph");
    const pose_graph::PoseGraphFile file = pose_graph::readPoseGraph(a->graph);
    if (file.dimension != 3)
      throw TrajectoryError(a->graph + ": a 2D graph; loops of an SE(3) keyframe graph expected");
    const auto keyframes = loadTrajectory(a->keyframes, "--keyframes");
    const auto reference = loadTrajectory(a->reference, "--reference");
    const pose_graph::Graph3D& g = file.graph3d;
    if (keyframes.size() != static_cast<std::size_t>(g.size()))
      throw TrajectoryError(a->keyframes + ": " + std::to_string(keyframes.size()) +
                            " keyframes for a graph of " + std::to_string(g.size()) + " nodes");
    // keyframes.tum lists the keyframes by increasing id, as the graph's node ids sort.
    std::vector<std::int64_t> ids = g.ids;
    std::sort(ids.begin(), ids.end());
    std::map<std::int64_t, std::int64_t> stamp_of;
    for (std::size_t i = 0; i < ids.size(); ++i) stamp_of[ids[i]] = keyframes[i].stamp_ns;
    // Loop edges join non-consecutive keyframes; odometry edges join each to the next.
    std::vector<RelativeMeasurement> loops;
    for (const auto& e : g.edges) {
      const std::int64_t from = g.ids[static_cast<std::size_t>(e.from)];
      const std::int64_t to = g.ids[static_cast<std::size_t>(e.to)];
      const auto fi = std::lower_bound(ids.begin(), ids.end(), from) - ids.begin();
      const auto ti = std::lower_bound(ids.begin(), ids.end(), to) - ids.begin();
      if (std::abs(ti - fi) == 1) continue;
      loops.push_back({stamp_of.at(from), stamp_of.at(to), e.measurement});
    }
    const LoopCheckResult r = checkLoops(loops, reference, a->check);
    Summary s("loop closures against the reference");
    s.row("loops",
          std::to_string(r.loops) + " (" + std::to_string(r.checked) + " with reference poses)");
    s.row("false", std::to_string(r.false_loops) + " (error > " +
                       Summary::num(a->check.max_error_m, 3) + " m or " +
                       Summary::num(a->check.max_error_deg, 1) + " deg)");
    s.row("precision", r.checked
                           ? Summary::num(100.0 * static_cast<double>(r.checked - r.false_loops) /
                                              static_cast<double>(r.checked),
                                          1) +
                                 " %"
                           : std::string("n/a"));
    s.stats("translation", r.translation, "m", 4);
    s.stats("rotation", r.rotation_deg, "deg", 3);
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["loops"] = r.loops;
      j["checked"] = r.checked;
      j["false"] = r.false_loops;
      j["precision"] = r.checked ? static_cast<double>(r.checked - r.false_loops) /
                                       static_cast<double>(r.checked)
                                 : 0.0;
      j["worst_true_error_m"] = r.worst_true_m;
      j["translation_rmse_m"] = r.translation.rmse;
      j["rotation_max_deg"] = r.rotation_deg.max;
      std::cout << j.dump(2) << "\n";
    }
    result = 0;
  });
}

}  // namespace

void addEvalCommand(CLI::App& app, int& result) {
  auto* eval = app.add_subcommand("eval", "accuracy of trajectories and maps against references");
  eval->require_subcommand(1);
  addRelations(*eval, result);
  addAte(*eval, result);
  addRpe(*eval, result);
  addHeading(*eval, result);
  addLandmarks(*eval, result);
  addLoops(*eval, result);
}

}  // namespace tessera::app
