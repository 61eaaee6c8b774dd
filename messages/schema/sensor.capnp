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

# Wheel encoders of a differential-drive base: cumulative tick counts since the driver started
# (Int64: they never wrap in practice; a count that jumps backwards means the driver restarted
# and consumers treat it as a reset). Positive ticks = that wheel rolling forward. The encoder's
# resolution and the base's nominal geometry travel with the counts, so a recording is
# self-describing (as LaserScan carries its mount); a consumer may still override the
# geometry with its own calibration.
struct WheelTicks {
  header @0 :Common.Header;        # frameId = base_link; stamp = when the counts were latched
  left @1 :Int64;                  # cumulative ticks of the left wheel
  right @2 :Int64;                 # cumulative ticks of the right wheel
  ticksPerRevolution @3 :Float64;  # ticks per wheel revolution (> 0)
  wheelRadius @4 :Float64;         # [m] nominal wheel radius (> 0)
  wheelBase @5 :Float64;           # [m] nominal distance between the wheels' contact points
}

# One inertial sample in the IMU frame (x forward, y left, z up; REP-103). Each value is the
# sensor's mean over the interval since its previous sample (an integrating sensor), so
# integrating rate x (stamp - previous stamp) gives the angle turned. A quantity the sensor does
# not measure, or a reading it flags as invalid, is NaN: consumers skip NaN values, never
# integrate them.
struct ImuSample {
  header @0 :Common.Header;        # frameId = imu (aligned with base_link in the simulator)
  angularVelocityX @1 :Float64;    # [rad/s]
  angularVelocityY @2 :Float64;    # [rad/s]
  angularVelocityZ @3 :Float64;    # [rad/s] yaw rate, counter-clockwise positive
  linearAccelerationX @4 :Float64; # [m/s^2] specific force (includes gravity)
  linearAccelerationY @5 :Float64; # [m/s^2]
  linearAccelerationZ @6 :Float64; # [m/s^2]
}

# A mobile base's own sensors and its driver's safety state (e.g. create_base). Published when
# something changes and at least twice a second while the base streams.
struct BaseStatus {
  header @0 :Common.Header;        # frameId = base_link
  bumpLeft @1 :Bool;
  bumpRight @2 :Bool;
  wheelDropLeft @3 :Bool;
  wheelDropRight @4 :Bool;
  cliffLeft @5 :Bool;
  cliffFrontLeft @6 :Bool;
  cliffFrontRight @7 :Bool;
  cliffRight @8 :Bool;
  batteryVoltage @9 :Float64;      # [V]
  batteryCurrent @10 :Float64;     # [A], negative while discharging
  batteryCharge @11 :Float64;      # [Ah]
  batteryCapacity @12 :Float64;    # [Ah]
  charging @13 :Bool;
  moving @14 :Bool;                # the wheels were last told to turn
  stopReason @15 :Text;            # why the driver last stopped the wheels ("" if it did not)
}
