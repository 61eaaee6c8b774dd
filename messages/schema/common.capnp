# Tessera common message types. Evolve by Cap'n Proto rules: add fields, never renumber.
@0xe0e29111a23fffe7;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

# Every message starts with a header.
struct Header {
  stampNs @0 :Int64;   # runtime clock time in nanoseconds (simulated time in simulation/replay)
  frameId @1 :Text;    # REP-105 frame name: map, odom, base_link, laser, camera
  seq @2 :UInt64;      # per-publisher sequence number, starting at 0
}

# Planar pose with row-major 3x3 covariance over (x [m], y [m], theta [rad]).
struct Pose2D {
  x @0 :Float64;
  y @1 :Float64;
  theta @2 :Float64;
  covariance @3 :List(Float64);  # 9 values, row-major; empty means unknown
}

# Planar velocity in the child frame: forward speed [m/s], lateral [m/s], yaw rate [rad/s].
struct Twist2D {
  vx @0 :Float64;
  vy @1 :Float64;
  omega @2 :Float64;
}

# A velocity command (cmd_vel).
struct Twist {
  header @0 :Header;
  twist @1 :Twist2D;
}

# A pose with its own header, e.g. a ground-truth pose from the simulator.
struct PoseStamped {
  header @0 :Header;
  pose @1 :Pose2D;
}

# Ground truth from a simulator or a motion-capture system; frame is "map" (world).
struct GroundTruthPose {
  header @0 :Header;
  pose @1 :Pose2D;
  childFrameId @2 :Text;  # normally base_link
}

# Opaque payload for benchmarks and tests: no schema cost beyond one Data field.
struct Blob {
  header @0 :Header;
  payload @1 :Data;
}
