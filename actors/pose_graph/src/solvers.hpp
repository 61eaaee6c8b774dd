// The solver stages behind optimize(); each returns what it did and changes poses in place.
#pragma once

#include <tessera/pose_graph/optimizer.hpp>

namespace tessera::pose_graph::detail {

struct StageResult {
  int iterations = 0;
  bool converged = false;
  std::string message;
};

StageResult runSgd(Graph2D& graph, const SgdOptions& options);
StageResult runSgd(Graph3D& graph, const SgdOptions& options);
StageResult runCeres(Graph2D& graph, const CeresOptions& options);
StageResult runCeres(Graph3D& graph, const CeresOptions& options);

}  // namespace tessera::pose_graph::detail
