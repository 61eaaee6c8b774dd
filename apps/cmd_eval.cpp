// `tessera eval relations|ate|merged|rpe|landmarks|loops`: accuracy of a trajectory or landmark map
// against a reference. Without --json the summary goes to stdout; with --json stdout holds exactly
// one JSON object and the summary goes to stderr, so the output can be piped into other tools. Exit
// codes: 0 ok; 2 usage errors (bad option values, an input file that does not exist); 1 bad input
// contents (malformed line: the message names file:line), nothing to compare, or an output file
// (--plot) that cannot be written.
#include "cli_inputs.hpp"
#include "commands.hpp"

#include <tessera/datasets/relations.hpp>
#include <tessera/evaluation/landmark_io.hpp>
#include <tessera/evaluation/loop_metrics.hpp>
#include <tessera/evaluation/map_metrics.hpp>
#include <tessera/evaluation/trajectory_metrics.hpp>
#include <tessera/io/atomic_file.hpp>
#include <tessera/mapping/map_io.hpp>
#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
#include <tessera/runtime/options.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
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
  /// A line as it is (tables).
  void line(const std::string& text) { out_ << text << "\n"; }
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

// `eval relations --plot`: an SVG chart of the mean translation error per time bin.
namespace eval_relations_plot {

struct Series {
  std::string label;  ///< the trajectory file as given on the command line
  std::vector<RelationsBin> bins;
  RelationsResult result;
};

std::string xmlEscape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

/// A round tick spacing (1, 2 or 5 × 10^k) giving about `ticks` intervals over [0, range].
double tickStep(double range, int ticks) {
  const double raw = range / ticks;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (raw <= m * magnitude) return m * magnitude;
  return 10.0 * magnitude;
}

std::string tickLabel(double v, double step) {
  const int digits = std::max(0, static_cast<int>(-std::floor(std::log10(step) + 1e-9)));
  return Summary::num(v, digits);
}

/// The chart as SVG text: one <path class="series"> (and its dots) per series.
std::string svg(const std::vector<Series>& series, double width_s, const std::string& relations,
                std::size_t relation_count) {
  static const char* const kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                         "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};
  constexpr double kWidth = 960, kLeft = 80, kRight = 30, kTop = 70, kPlotHeight = 360;
  constexpr double kPlotWidth = kWidth - kLeft - kRight;
  constexpr double kLegendLine = 20;
  const double height = kTop + kPlotHeight + 70 + kLegendLine * static_cast<double>(series.size());

  std::size_t bin_count = 0;
  double y_max = 0;
  for (const Series& s : series) {
    bin_count = std::max(bin_count, s.bins.size());
    for (const RelationsBin& b : s.bins)
      if (b.count > 0) y_max = std::max(y_max, b.translation_mean);
  }
  const double x_max = std::max(1.0, static_cast<double>(bin_count)) * width_s;
  const double y_step = tickStep(y_max > 0 ? y_max * 1.05 : 1.0, 6);
  const double y_top = y_step * std::ceil((y_max > 0 ? y_max * 1.05 : 1.0) / y_step);
  const double x_step = tickStep(x_max, 10);
  const auto px = [&](double t) { return kLeft + t / x_max * kPlotWidth; };
  const auto py = [&](double m) { return kTop + kPlotHeight - m / y_top * kPlotHeight; };
  const auto f1 = [](double v) { return Summary::num(v, 1); };

  std::ostringstream o;
  o << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << kWidth << "\" height=\""
    << f1(height) << "\" viewBox=\"0 0 " << kWidth << ' ' << f1(height)
    << "\" font-family=\"sans-serif\" font-size=\"12\">\n"
    << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
    << "<text x=\"" << kWidth / 2 << "\" y=\"26\" text-anchor=\"middle\" font-size=\"16\">"
    << "Relations error over time: mean translation error per " << width_s << " s bin</text>\n"
    << "<text x=\"" << kWidth / 2 << "\" y=\"46\" text-anchor=\"middle\" fill=\"#555\">"
    << xmlEscape(relations) << " (" << relation_count
    << " relations, binned by t1; Kümmerle et al. 2009)</text>\n";
  // Grid and y ticks [m].
  const int y_ticks = static_cast<int>(std::lround(y_top / y_step));
  for (int i = 0; i <= y_ticks; ++i) {
    const double v = i * y_step;
    o << "<line x1=\"" << kLeft << "\" y1=\"" << f1(py(v)) << "\" x2=\"" << kLeft + kPlotWidth
      << "\" y2=\"" << f1(py(v)) << "\" stroke=\"#e5e5e5\"/>\n"
      << "<text x=\"" << kLeft - 8 << "\" y=\"" << f1(py(v) + 4) << "\" text-anchor=\"end\">"
      << tickLabel(v, y_step) << "</text>\n";
  }
  // x ticks [s].
  const int x_ticks = static_cast<int>(std::floor(x_max / x_step + 1e-9));
  for (int i = 0; i <= x_ticks; ++i) {
    const double t = i * x_step;
    o << "<line x1=\"" << f1(px(t)) << "\" y1=\"" << kTop + kPlotHeight << "\" x2=\"" << f1(px(t))
      << "\" y2=\"" << kTop + kPlotHeight + 5 << "\" stroke=\"black\"/>\n"
      << "<text x=\"" << f1(px(t)) << "\" y=\"" << kTop + kPlotHeight + 19
      << "\" text-anchor=\"middle\">" << tickLabel(t, x_step) << "</text>\n";
  }
  // Axes and their titles.
  o << "<line x1=\"" << kLeft << "\" y1=\"" << kTop << "\" x2=\"" << kLeft << "\" y2=\""
    << kTop + kPlotHeight << "\" stroke=\"black\"/>\n"
    << "<line x1=\"" << kLeft << "\" y1=\"" << kTop + kPlotHeight << "\" x2=\""
    << kLeft + kPlotWidth << "\" y2=\"" << kTop + kPlotHeight << "\" stroke=\"black\"/>\n"
    << "<text x=\"" << kLeft + kPlotWidth / 2 << "\" y=\"" << kTop + kPlotHeight + 40
    << "\" text-anchor=\"middle\">time since the first relation [s]</text>\n"
    << "<text x=\"20\" y=\"" << kTop + kPlotHeight / 2
    << "\" text-anchor=\"middle\" transform=\"rotate(-90 20 " << kTop + kPlotHeight / 2
    << ")\">mean translation error [m]</text>\n";
  // One line per trajectory through its bin centres, broken at empty bins.
  for (std::size_t k = 0; k < series.size(); ++k) {
    const char* colour = kColours[k % std::size(kColours)];
    std::ostringstream path, dots;
    bool pen_down = false;
    for (const RelationsBin& b : series[k].bins) {
      if (b.count == 0) {
        pen_down = false;
        continue;
      }
      const std::string x = f1(px(b.start_s + width_s / 2)), y = f1(py(b.translation_mean));
      path << (pen_down ? " L" : (path.tellp() > 0 ? " M" : "M")) << x << ' ' << y;
      pen_down = true;
      dots << "<circle cx=\"" << x << "\" cy=\"" << y << "\" r=\"3\"/>";
    }
    o << "<g fill=\"" << colour << "\">\n<path class=\"series\" d=\"" << path.str()
      << "\" fill=\"none\" stroke=\"" << colour << "\" stroke-width=\"2\"/>\n"
      << dots.str() << "\n</g>\n";
    const RelationsResult& r = series[k].result;
    const double y = kTop + kPlotHeight + 62 + kLegendLine * static_cast<double>(k);
    o << "<line x1=\"" << kLeft << "\" y1=\"" << f1(y - 4) << "\" x2=\"" << kLeft + 24 << "\" y2=\""
      << f1(y - 4) << "\" stroke=\"" << colour << "\" stroke-width=\"2\"/>\n"
      << "<text x=\"" << kLeft + 32 << "\" y=\"" << f1(y) << "\">"
      << xmlEscape(series[k].label + ": mean " + Summary::num(r.translation.mean, 4) + " ± " +
                   Summary::num(r.translation.std, 4) + " m, " +
                   Summary::num(r.rotation_deg.mean, 2) + "° (" + std::to_string(r.matched) +
                   " relations)")
      << "</text>\n";
  }
  o << "</svg>\n";
  return o.str();
}

/// Fails early, as a usage error, when `path` cannot be a new file: its folder is missing.
void requireWritableTarget(const std::string& path, const char* option) {
  if (path.empty()) throw ConfigError(std::string(option) + ": empty file name");
  std::error_code ec;
  const fs::path target(path);
  const fs::path folder = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  if (!fs::is_directory(folder, ec))
    throw ConfigError(std::string(option) + " " + path + ": the folder " + folder.string() +
                      (fs::exists(folder, ec) ? " is not a folder" : " does not exist"));
  if (fs::is_directory(target, ec))
    throw ConfigError(std::string(option) + " " + path + ": is a folder, not a file");
}

}  // namespace eval_relations_plot

void addRelations(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "relations", "Kümmerle et al. 2009 relations metric of a trajectory (TUM file)");
  struct Args {
    std::vector<std::string> trajectories;
    std::string relations, plot;
    double max_gap_s = RelationsOptions{}.max_gap_s;
    double time_offset_s = 0;
    double max_speed = 0;
    double bins_s = 0;
    bool json = false;
  };
  constexpr double kDefaultPlotBinS = 300;
  auto a = std::make_shared<Args>();
  cmd->add_option("--trajectory", a->trajectories,
                  "estimated trajectory, TUM format; repeat it to add trajectories to --plot "
                  "(the summary and JSON are for the first)")
      ->required();
  cmd->add_option("--relations", a->relations, "relations file 't1 t2 dx dy dz roll pitch yaw'")
      ->required();
  cmd->add_option("--max-gap", a->max_gap_s,
                  "[s] relation times between trajectory poses further apart are not matched "
                  "(0: no limit)")
      ->capture_default_str();
  cmd->add_option("--time-offset", a->time_offset_s,
                  "[s] added to the trajectory stamps to bring them to the relations' time base")
      ->capture_default_str();
  auto* max_speed = cmd->add_option(
      "--max-speed", a->max_speed,
      "[m/s] also report the relations whose true displacement over |t2 - t1| is at most this "
      "(faster ones are inconsistent with their timestamps); 0: off");
  auto* bins = cmd->add_option("--bins", a->bins_s,
                               "[s] also report the mean error per bin of this width, by t1");
  auto* plot = cmd->add_option(
      "--plot", a->plot,
      "write an SVG chart of the mean translation error per bin (--bins, default 300 s) "
      "against time, one line per --trajectory");
  cmd->add_flag("--json", a->json, "print one JSON object on stdout");
  cmd->callback([a, &result, max_speed, bins, plot] {
    namespace rp = eval_relations_plot;
    if (!(a->max_gap_s >= 0)) throw ConfigError("--max-gap must be a number >= 0");
    requireFinite(a->time_offset_s, "--time-offset");
    const bool split = max_speed->count() > 0 && a->max_speed != 0;
    if (max_speed->count() > 0 && (!(a->max_speed >= 0) || !std::isfinite(a->max_speed)))
      throw ConfigError("--max-speed must be a number >= 0 (m/s; 0: off)");
    const bool binned = bins->count() > 0;
    if (binned && (!(a->bins_s > 0) || !std::isfinite(a->bins_s)))
      throw ConfigError("--bins must be a positive number of seconds");
    const bool plotted = plot->count() > 0;
    if (plotted) rp::requireWritableTarget(a->plot, "--plot");
    const double bin_s = binned ? a->bins_s : kDefaultPlotBinS;

    std::vector<std::vector<TumPose>> trajectories;
    for (const std::string& path : a->trajectories)
      trajectories.push_back(loadTrajectory(path, "--trajectory"));
    const std::vector<PoseRelation> relations = loadPoseRelations(a->relations, "--relations");
    RelationsOptions options;
    options.max_gap_s = a->max_gap_s;
    options.time_offset_s = a->time_offset_s;
    options.max_speed = split ? a->max_speed : 0.0;
    std::vector<rp::Series> series;
    for (std::size_t k = 0; k < trajectories.size(); ++k) {
      rp::Series& s = series.emplace_back();
      s.label = a->trajectories[k];
      s.result = computeRelationsError(trajectories[k], relations, options);
      if (binned || plotted) {
        try {
          s.bins = binRelationErrors(s.result.errors, bin_s);
        } catch (const MetricError& e) {
          std::ostringstream width;
          width << bin_s;
          throw ConfigError("--bins " + width.str() + ": " + e.what());
        }
      }
    }
    if (plotted) {
      // Atomic: a temporary file beside the target, renamed over it once complete. Errors
      // (io::FileWriteError) name the file and the reason.
      tessera::io::writeFileAtomically(a->plot,
                                       rp::svg(series, bin_s, a->relations, relations.size()));
    }
    const RelationsResult& r = series.front().result;

    Summary s("relations metric (Kümmerle et al. 2009)");
    s.row("trajectory",
          a->trajectories.front() + " (" + std::to_string(trajectories.front().size()) + " poses)");
    s.row("relations", a->relations + " (" + std::to_string(r.relations) + ")");
    s.row("matched", std::to_string(r.matched) + " of " + std::to_string(r.relations) + " (" +
                         std::to_string(r.outside) + " outside the trajectory, " +
                         std::to_string(r.in_gap) + " in gaps > " + Summary::num(a->max_gap_s, 1) +
                         " s)");
    s.meanStd("translation", r.translation, "m", 4);
    s.meanStd("translation²", r.translation_squared, "m²", 4);
    s.meanStd("rotation", r.rotation_deg, "deg", 3);
    s.meanStd("rotation²", r.rotation_squared_deg, "deg²", 3);
    if (split) {
      s.row("consistent",
            std::to_string(r.matched - r.inconsistent) + " of " + std::to_string(r.matched) +
                " matched (" + std::to_string(r.inconsistent) + " faster than " +
                Summary::num(a->max_speed, 2) + " m/s: inconsistent with their timestamps)");
      s.meanStd("  translation", r.consistent_translation, "m", 4);
      s.meanStd("  rotation", r.consistent_rotation_deg, "deg", 3);
    }
    for (std::size_t k = 1; k < series.size(); ++k) {
      const RelationsResult& o = series[k].result;
      s.row("also", series[k].label + ": " + Summary::num(o.translation.mean, 4) + " ± " +
                        Summary::num(o.translation.std, 4) + " m, " +
                        Summary::num(o.rotation_deg.mean, 3) + " ± " +
                        Summary::num(o.rotation_deg.std, 3) + " deg (" + std::to_string(o.matched) +
                        " matched)");
    }
    if (binned) {
      s.line("  error by t1, " + Summary::num(bin_s, 1) + " s bins from the first relation:");
      std::ostringstream table;
      table << "  " << std::setw(12) << "start s" << std::setw(8) << "count" << std::setw(10)
            << "mean m" << std::setw(10) << "mean deg";
      s.line(table.str());
      for (const RelationsBin& b : series.front().bins) {
        std::ostringstream row;
        row << "  " << std::setw(12) << Summary::num(b.start_s, 1) << std::setw(8) << b.count
            << std::setw(10) << (b.count ? Summary::num(b.translation_mean, 4) : "-")
            << std::setw(10) << (b.count ? Summary::num(b.rotation_mean_deg, 3) : "-");
        s.line(row.str());
      }
    }
    if (plotted) s.row("plot", a->plot + " (" + Summary::num(bin_s, 1) + " s bins)");
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["relations"] = r.relations;
      j["matched"] = r.matched;
      j["outside"] = r.outside;
      j["in_gap"] = r.in_gap;
      // The four statistics under the same keys for all relations and the consistent ones.
      const auto put = [](nlohmann::json& o, const ErrorStats& t, const ErrorStats& t2,
                          const ErrorStats& rot, const ErrorStats& rot2) {
        o["trans_mean_m"] = t.mean;
        o["trans_std_m"] = t.std;
        o["trans2_mean"] = t2.mean;
        o["trans2_std"] = t2.std;
        o["rot_mean_deg"] = rot.mean;
        o["rot_std_deg"] = rot.std;
        o["rot2_mean"] = rot2.mean;
        o["rot2_std"] = rot2.std;
      };
      put(j, r.translation, r.translation_squared, r.rotation_deg, r.rotation_squared_deg);
      if (split) {
        j["inconsistent_count"] = r.inconsistent;
        nlohmann::json c{{"max_speed", a->max_speed}, {"count", r.consistent_translation.count}};
        put(c, r.consistent_translation, r.consistent_translation_squared,
            r.consistent_rotation_deg, r.consistent_rotation_squared_deg);
        j["consistent"] = c;
      }
      if (binned) {
        j["bin_s"] = bin_s;
        j["bins"] = nlohmann::json::array();
        for (const RelationsBin& b : series.front().bins)
          j["bins"].push_back({{"start_s", b.start_s},
                               {"count", b.count},
                               {"trans_mean_m", b.translation_mean},
                               {"rot_mean_deg", b.rotation_mean_deg}});
      }
      if (series.size() > 1) {
        j["other_trajectories"] = nlohmann::json::array();
        for (std::size_t k = 1; k < series.size(); ++k) {
          const RelationsResult& o = series[k].result;
          j["other_trajectories"].push_back({{"trajectory", series[k].label},
                                             {"matched", o.matched},
                                             {"trans_mean_m", o.translation.mean},
                                             {"trans_std_m", o.translation.std},
                                             {"rot_mean_deg", o.rotation_deg.mean},
                                             {"rot_std_deg", o.rotation_deg.std}});
        }
      }
      if (plotted) j["plot"] = a->plot;
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

void addMerged(CLI::App& eval, int& result) {
  auto* cmd = eval.add_subcommand(
      "merged",
      "ATE of several robots' trajectories in one merged frame: one rigid alignment for all");
  struct Args {
    std::vector<std::string> estimates, references;
    double max_diff_s = AssociationOptions{}.max_difference_s;
    bool planar = false, spatial = false, json = false;
    std::string map, walls;
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--map", a->map,
                  "the merged map (map_server YAML): scored against --walls moved into the merged "
                  "frame by the alignment");
  cmd->add_option("--walls", a->walls,
                  "the true walls, 'x0 y0 x1 y1' lines in the references' frame (world_writer)");
  cmd->add_option("--estimate", a->estimates,
                  "a robot's trajectory in the merged frame, TUM format; one per robot")
      ->required();
  cmd->add_option("--reference", a->references,
                  "its ground truth, TUM format, in the order of --estimate; the references "
                  "share one frame (e.g. the simulator's world)")
      ->required();
  cmd->add_option("--max-diff", a->max_diff_s, "[s] largest stamp difference of a pose pair")
      ->capture_default_str();
  auto* p = cmd->add_flag("--2d", a->planar, "SE(2): compare in the xy plane (default: automatic)");
  auto* s3 = cmd->add_flag("--3d", a->spatial, "SE(3) even for planar files");
  p->excludes(s3);
  cmd->add_flag("--json", a->json, "print one JSON object on stdout");
  cmd->callback([a, &result] {
    if (!(a->max_diff_s >= 0)) throw ConfigError("--max-diff must be a number >= 0");
    if (a->estimates.size() != a->references.size())
      throw ConfigError("eval merged: " + std::to_string(a->estimates.size()) + " --estimate but " +
                        std::to_string(a->references.size()) +
                        " --reference; give one reference per estimate");
    std::vector<std::pair<std::vector<mapping::TumPose>, std::vector<mapping::TumPose>>> pairs;
    for (std::size_t k = 0; k < a->estimates.size(); ++k)
      pairs.emplace_back(loadTrajectory(a->estimates[k], "--estimate"),
                         loadTrajectory(a->references[k], "--reference"));
    AteOptions options;
    options.association.max_difference_s = a->max_diff_s;
    options.dimension = dimensionOf(a->planar, a->spatial);
    if (a->map.empty() != a->walls.empty())
      throw ConfigError("eval merged: --map and --walls go together");
    const JointAteResult r = computeJointAte(pairs, options);
    Summary s("ATE in one merged frame (one alignment for every trajectory)");
    std::optional<MapWallScore> walls;
    if (!a->map.empty()) {
      requireFile(a->walls, "--walls");
      auto segments = readWalls(a->walls);
      // Into the merged frame: the inverse of the alignment (estimate -> reference).
      const auto toMap = [&](const Eigen::Vector2d& p) -> Eigen::Vector2d {
        return r.alignment.unapply({p.x(), p.y(), 0}).head<2>();
      };
      for (auto& w : segments) {
        w.a = toMap(w.a);
        w.b = toMap(w.b);
      }
      requireFile(a->map, "--map");
      walls = scoreMapAgainstWalls(mapping::loadMap(a->map), segments);
    }
    s.row("alignment", modeName(r.planar) + ", " + std::to_string(pairs.size()) + " trajectories");
    nlohmann::json list = nlohmann::json::array();
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      s.row(a->estimates[k], "merged frame rmse " + Summary::num(r.joint[k].rmse, 4) + " m, max " +
                                 Summary::num(r.joint[k].max, 4) + " m; aligned alone rmse " +
                                 Summary::num(r.alone[k].translation.rmse, 4) + " m (" +
                                 std::to_string(r.alone[k].pairs) + " pairs)");
      nlohmann::json j;
      j["estimate"] = a->estimates[k];
      j["reference"] = a->references[k];
      j["pairs"] = r.alone[k].pairs;
      j["merged_rmse_m"] = r.joint[k].rmse;
      j["merged_max_m"] = r.joint[k].max;
      j["alone_rmse_m"] = r.alone[k].translation.rmse;
      list.push_back(j);
    }
    if (walls) {
      s.row("map", a->map);
      s.row("wall cells found", Summary::num(walls->wall_cells_found, 4) + " of the " +
                                    std::to_string(walls->wall_points_seen) +
                                    " true wall points observed");
      s.row("false wall cells", std::to_string(walls->false_wall_cells) + " of " +
                                    std::to_string(walls->occupied_cells) + " occupied, " +
                                    std::to_string(walls->doubled_wall_cells) +
                                    " of them a wall drawn twice, " +
                                    std::to_string(walls->displaced_wall_cells) +
                                    " a wall drawn once beside its place (within 1 m)");
    }
    s.print(a->json);
    if (a->json) {
      nlohmann::json j;
      j["mode"] = r.planar ? "se2" : "se3";
      j["trajectories"] = list;
      if (walls) {
        j["wall_cells_found"] = walls->wall_cells_found;
        j["occupied_cells"] = walls->occupied_cells;
        j["false_wall_cells"] = walls->false_wall_cells;
        j["doubled_wall_cells"] = walls->doubled_wall_cells;
        j["displaced_wall_cells"] = walls->displaced_wall_cells;
      }
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
  addMerged(*eval, result);
  addRpe(*eval, result);
  addHeading(*eval, result);
  addLandmarks(*eval, result);
  addLoops(*eval, result);
}

}  // namespace tessera::app
