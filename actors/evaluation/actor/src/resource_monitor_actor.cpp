#include <tessera/evaluation/resource_log.hpp>
#include <tessera/evaluation/resource_monitor_actor.hpp>

#include <tessera/msg/keyframe.capnp.h>
#include <tessera/msg/sensor.capnp.h>
#include <tessera/msg/submap.capnp.h>
#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/periodic.hpp>
#include <tessera/runtime/process_stats.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>

namespace tessera::evaluation {

ResourceMonitorActor::ResourceMonitorActor(ResourceMonitorOptions options)
    : options_(std::move(options)) {
  if (!(options_.period_s > 0.0) || !std::isfinite(options_.period_s))
    throw ConfigError("resource_monitor: period_s must be > 0 s, got " +
                      std::to_string(options_.period_s));
  if (options_.file.empty()) throw ConfigError("resource_monitor: file must not be empty");
  if (options_.graph && options_.keyframes)
    throw ConfigError("resource_monitor: graph and keyframes both true; the counts are of one");
}

ResourceMonitorActor::~ResourceMonitorActor() = default;

void ResourceMonitorActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::LaserScan>("scan", MailboxPolicy::reliable(),
                                [this](const Message<msg::LaserScan>&) { ++scans_; });
  if (options_.graph)
    ctx.subscribe<msg::SubmapPoses>(
        "submap_poses", MailboxPolicy::keepLatest(1), [this](const Message<msg::SubmapPoses>& m) {
          const auto poses = m->getPoses();
          graph_nodes_ = poses.size();
          if (poses.size() > 0)
            submaps_ = std::max<std::uint64_t>(submaps_, poses[poses.size() - 1].getId() + 1);
          trimmed_ = m->getTrimmed().size();
          if (trimmed_ > 0) {
            const auto t = m->getTrimmed();
            submaps_ = std::max<std::uint64_t>(submaps_, t[t.size() - 1] + 1);
          }
        });
  if (options_.keyframes)
    ctx.subscribe<msg::KeyframePoses>("keyframe_poses", MailboxPolicy::keepLatest(1),
                                      [this](const Message<msg::KeyframePoses>& m) {
                                        const auto poses = m->getPoses();
                                        graph_nodes_ = poses.size();
                                        if (poses.size() > 0)
                                          submaps_ = std::max<std::uint64_t>(
                                              submaps_, poses[poses.size() - 1].getId() + 1);
                                        trimmed_ = submaps_ - std::min(submaps_, graph_nodes_);
                                      });
  addPeriodicTimer(ctx, options_.period_s, [this] { sample(); });
}

void ResourceMonitorActor::start() {
  first_ = ctx_->now();
  if (!ctx_->outputDir().empty()) {
    path_ = (std::filesystem::path(ctx_->outputDir()) / options_.file).string();
    try {
      file_ = std::make_unique<io::AtomicFile>(path_);
      file_->stream() << kResourceLogHeader << "\n";
    } catch (const io::FileWriteError& e) {
      error_ = e.what();
      std::cerr << ctx_->name() << ": " << error_ << "\n";
    }
  }
  sample();
}

void ResourceMonitorActor::sample() {
  rss_mb_ = currentRssMegabytes();
  cpu_s_ = processCpuSeconds();
  ++rows_;
  if (!file_) return;
  try {
    file_->stream() << std::fixed << std::setprecision(3) << nanosToSeconds(ctx_->now() - first_)
                    << ',' << rss_mb_ << ',' << cpu_s_ << ',' << scans_ << ',' << submaps_ << ','
                    << graph_nodes_ << ',' << trimmed_ << '\n';
    file_->flush();
  } catch (const io::FileWriteError& e) {
    error_ = e.what();
    std::cerr << ctx_->name() << ": " << error_ << "\n";
    file_.reset();  // the temporary file goes; the run goes on
  }
}

void ResourceMonitorActor::stop() {
  sample();
  if (!file_) return;
  try {
    file_->commit();
  } catch (const io::FileWriteError& e) {
    error_ = e.what();
    std::cerr << ctx_->name() << ": " << error_ << "\n";
  }
  file_.reset();
}

void ResourceMonitorActor::summarize(Summary& out) const {
  out["rows"] = static_cast<std::int64_t>(rows_);
  out["rss_mb"] = rss_mb_;
  out["scans"] = static_cast<std::int64_t>(scans_);
  out["graph_nodes"] = static_cast<std::int64_t>(graph_nodes_);
  out["submaps_trimmed"] = static_cast<std::int64_t>(trimmed_);
  if (!path_.empty()) out["path"] = path_;
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("resource_monitor", ResourceMonitorActor, ResourceMonitorOptions,
                       "samples this process's memory, CPU and graph size on the run's clock "
                       "into a CSV (soak tests)");

}  // namespace tessera::evaluation
