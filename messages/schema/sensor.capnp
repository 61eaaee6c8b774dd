# Sensor messages. Evolve by Cap'n Proto rules: add fields, never renumber.
@0xaec298bf9ac7c547;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# One planar laser sweep, ROS sensor_msgs/LaserScan semantics. Beam i points at
# angleMin + i * angleIncrement [rad] in the laser frame (counter-clockwise positive).
# A beam with no return holds +inf; NaN marks an invalid reading. Both are skipped by mappers.
struct LaserScan {
  header @0 :Common.Header;
  angleMin @1 :Float32;
  angleIncrement @2 :Float32;
  rangeMin @3 :Float32;        # [m] readings below are invalid
  rangeMax @4 :Float32;        # [m] readings at or above are no-return
  ranges @5 :List(Float32);    # [m]
  intensities @6 :List(Float32);  # empty when the sensor gives none
  scanTimeS @7 :Float32;       # [s] time for one sweep (0: instantaneous)
  # Laser mounting in base_link (x forward, y left) so consumers need no TF tree.
  mountX @8 :Float32;
  mountY @9 :Float32;
  mountTheta @10 :Float32;
}

# Wheel odometry: pose of base_link in the odom frame, drifting without bound.
struct Odometry {
  header @0 :Common.Header;    # frameId = odom
  childFrameId @1 :Text;       # base_link
  pose @2 :Common.Pose2D;
  twist @3 :Common.Twist2D;
  twistCovariance @4 :List(Float64);  # 9 values, row-major, over (vx, vy, omega)
}
