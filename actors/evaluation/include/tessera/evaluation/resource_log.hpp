// The resource monitor's log (resources.csv, written by the resource_monitor actor): one row per
// sample of a run's own memory and CPU. Columns: t_s (run time since the first sample, s),
// rss_mb (resident memory, MiB), cpu_s (process CPU time, s), scans (laser scans received),
// submaps (made so far), graph_nodes (submaps in the latest optimised graph), trimmed (submaps
// trimmed by lifelong mapping). `tessera bench soak` reads it back.
#pragma once

#include <filesystem>
#include <string_view>
#include <vector>

namespace tessera::evaluation {

/// The header line, exactly as the monitor writes it.
inline constexpr std::string_view kResourceLogHeader =
    "t_s,rss_mb,cpu_s,scans,submaps,graph_nodes,trimmed";

struct ResourceSample {
  double t_s = 0, rss_mb = 0, cpu_s = 0;
  double scans = 0, submaps = 0, graph_nodes = 0, trimmed = 0;
};

/// Every row of `path`. Throws std::runtime_error naming the file (and line, and column) for a
/// missing or empty file, a header other than kResourceLogHeader, a row without exactly 7 finite
/// numbers (cut short, text, NaN), or a time earlier than the row before.
std::vector<ResourceSample> readResourceLog(const std::filesystem::path& path);

}  // namespace tessera::evaluation
