// Reading and writing pose graphs in the g2o and TORO text formats, straight into and out of the
// solvers' Graph2D / Graph3D (pose_graph.hpp): nodes in increasing id order, edges in file order
// (every edge non-robust: which edges are loop closures is the caller's policy), FIX lines as
// fixed nodes. Writers put vertices and FIX lines in increasing id order, edges in graph order.
//
// Formats (recognised from the content, never from the file name: some g2o files end in .graph):
//   g2o   VERTEX_SE2 id x y theta
//         EDGE_SE2 i j dx dy dtheta  I11 I12 I13 I22 I23 I33          (upper triangle, row-major)
//         VERTEX_SE3:QUAT id x y z qx qy qz qw
//         EDGE_SE3:QUAT i j dx dy dz qx qy qz qw  + 21 upper-triangular entries of the 6x6
//             information over (translation, rotation), row-major
//         FIX id                                                    (the node is `fixed`)
//   TORO  VERTEX2 id x y theta
//         EDGE2 i j dx dy dtheta  inf_ff inf_fs inf_ss inf_rr inf_fr inf_sr
//             f = forward (x), s = sideward (y), r = rotation (theta): the order is
//             I11 I12 I22 I33 I13 I23, NOT g2o's I11 I12 I13 I22 I23 I33 (TORO manual on
//             openslam.org; GTSAM dataset.cpp reads it the same way).
// An edge i -> j holds the pose of j in the frame of i in both formats (checked on the shared
// data: vertex 1 of M3500_P_toro.graph is vertex 0 composed with edge 0 -> 1). Units: metres,
// radians. Angles are stored as read (not wrapped), so a write/read round trip is exact.
//
// Reading rules (each has a test):
//  * '#' comment lines and blank lines are ignored. Tags of either family this reader does not
//    model (g2o VERTEX_XY, EDGE_SE2_XY, PARAMS_*, TORO VERTEX3/EDGE3/EQUIV, ...) are counted skips
//    in the io::ParseReport; a line whose tag belongs to neither family is also a counted skip.
//  * A file mixing g2o and TORO tags, or 2D and 3D elements, is a DatasetError.
//  * Wrong field counts, non-numbers, NaN/inf, ids outside [0, 2^31-1] (g2o stores ints), a
//    vertex defined twice, an edge from a vertex to itself: DatasetError naming file:line.
//  * Information matrices must be symmetric positive semidefinite (they are symmetric by
//    construction from the upper triangle; the smallest eigenvalue must be >= -1e-9 times the
//    largest magnitude). A violation is a DatasetError, not a skip: dropping a constraint could
//    disconnect the graph and would change the optimum silently.
//  * Quaternions are normalised (one of unit norm to rounding is kept bit for bit); one whose
//    norm is below 1e-6 (or not finite) is an error.
//  * In a file with vertices, an edge naming an undefined vertex is an error (reported with the
//    edge's line). In a file with NO vertices (e.g. SE-Sync's manhattan.g2o), initial poses are
//    built: the smallest id referenced sits at the origin, then each next id is chained through
//    the first odometry edge id-1 -> id (or the inverse of id -> id-1); vertices the chain
//    cannot reach (a gap in the ids) are then placed by a breadth-first walk over all remaining
//    edges from the placed ones. A vertex not connected to the first one at all is an error (its
//    component would float freely in any optimisation). Built headings are wrapped to (-pi, pi].
#pragma once

#include <tessera/io/text_reader.hpp>
#include <tessera/pose_graph/pose_graph.hpp>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <filesystem>
#include <map>
#include <vector>

namespace tessera::pose_graph {

enum class GraphFormat { kG2o, kToro };

// What one read produced. Exactly one of graph2d / graph3d is filled (dimension says which).
struct PoseGraphFile {
  GraphFormat format = GraphFormat::kG2o;
  int dimension = 2;
  Graph2D graph2d;
  Graph3D graph3d;
  std::size_t vertex_lines = 0;      // vertices defined in the file
  std::size_t chained_vertices = 0;  // built from odometry edges (file without vertices)
  std::size_t walked_vertices = 0;   // built through other edges (gaps in the chain)
  io::ParseReport report;            // records = vertex + edge + FIX lines
};

constexpr std::int64_t kMaxVertexId = 2147483647;

// Reads any supported file. Throws DatasetError (file:line) as described above, and when the
// file has no vertex or edge at all.
PoseGraphFile readPoseGraph(const std::filesystem::path& path);
PoseGraphFile readPoseGraph(io::TextReader& reader);
// Same, but the file must hold a graph of that dimension (else DatasetError).
Graph2D readPoseGraph2D(const std::filesystem::path& path, io::ParseReport* report = nullptr);
Graph3D readPoseGraph3D(const std::filesystem::path& path, io::ParseReport* report = nullptr);

// Writers: vertices by increasing id, then edges in order (then FIX lines for g2o). Numbers are
// printed in their shortest exact form, so reading the file back gives identical values.
// TORO has no FIX line and no 3D edge format here, so fixed nodes are not marked. Throws
// DatasetError if the file cannot be written or a value is not finite.
void writeG2o(const Graph2D& graph, const std::filesystem::path& path);
void writeG2o(const Graph3D& graph, const std::filesystem::path& path);
void writeToro(const Graph2D& graph, const std::filesystem::path& path);

}  // namespace tessera::pose_graph
