# Point-landmark messages (docs/algorithms.md#landmark-slam): range-bearing observations, drive controls of car-like
# robots, and landmark maps. Evolve by Cap'n Proto rules: add fields, never renumber.
@0x9833d95b83bfdbcd;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# One landmark seen from the sensor. Bearing is counter-clockwise from the sensor's x axis.
struct LandmarkObservation {
  id @0 :Int32;              # landmark identity when the sensor gives it; -1 = unknown
  range @1 :Float64;         # [m]
  bearing @2 :Float64;       # [rad] in (-pi, pi]
  rangeStd @3 :Float64;      # [m] 1-sigma the sensor claims (0 = unknown)
  bearingStd @4 :Float64;    # [rad]
}

# Everything the landmark sensor saw at one instant (possibly nothing).
struct LandmarkScan {
  header @0 :Common.Header;  # frameId = the sensor
  # Sensor mounting in base_link, so consumers need no TF tree.
  mountX @1 :Float64;
  mountY @2 :Float64;
  mountTheta @3 :Float64;
  observations @4 :List(LandmarkObservation);
}

# Control of a car-like (or differential-drive) base over the interval that starts at the
# stamp: speed of the reference point and front-wheel steering angle (the model of docs/algorithms.md#landmark-slam
# x += dt V cos(theta + gamma), y += dt V sin(theta + gamma), theta += dt V sin(gamma) / L).
# A differential-drive source fills turnRate instead and sets steering = 0, wheelbase = 0.
struct DriveControl {
  header @0 :Common.Header;
  speed @1 :Float64;         # [m/s]
  steering @2 :Float64;      # [rad] gamma; 0 for a differential drive
  wheelbase @3 :Float64;     # [m] L; 0 when not car-like
  turnRate @4 :Float64;      # [rad/s] for a differential drive
  dtS @5 :Float64;           # [s] how long the control applies (0 = until the next one)
}

struct Landmark {
  id @0 :Int32;
  x @1 :Float64;             # [m] in header.frameId
  y @2 :Float64;
  covariance @3 :List(Float64);  # 4 values, row-major (xx, xy, yx, yy); empty = unknown
}

# A set of point landmarks: ground truth from a simulator or dataset, or a SLAM estimate.
struct LandmarkMap {
  header @0 :Common.Header;  # frameId = map
  landmarks @1 :List(Landmark);
}
