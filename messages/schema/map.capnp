# Map messages. Evolve by Cap'n Proto rules: add fields, never renumber.
@0x875eaa34a24036c8;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# Occupancy grid as ROS nav_msgs/OccupancyGrid: cells row-major from the origin corner,
# row 0 at the origin's y, int8 values 0..100 = occupancy probability in percent, -1 = unknown.
struct OccupancyGrid {
  header @0 :Common.Header;    # frameId = map (or a submap frame)
  resolution @1 :Float32;      # [m/cell]
  width @2 :UInt32;            # cells along x
  height @3 :UInt32;           # cells along y
  origin @4 :Common.Pose2D;    # pose of cell (0,0)'s outer corner in frameId
  cells @5 :Data;              # width*height int8 values
}

# A sequence of planar poses, e.g. a planned route or an estimated trajectory.
struct Path {
  header @0 :Common.Header;
  poses @1 :List(Common.PoseStamped);
}
