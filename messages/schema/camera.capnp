# Environment camera network (docs/algorithms.md#simulated-motion-and-sensors): fixed ceiling cameras that see a marker on the robot.
# Evolve by Cap'n Proto rules: add fields, never renumber.
@0x9f0646620a43b2e5;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# What one camera reported at one frame time.
struct MarkerDetection {
  header @0 :Common.Header;   # frameId = "camera_<id>"
  cameraId @1 :Int32;
  detected @2 :Bool;          # false: the marker is in view but was missed, or out of view
  u @3 :Float64;              # [px] marker image position (column); valid when detected
  v @4 :Float64;              # [px] (row)
  pixelStd @5 :Float64;       # [px] 1-sigma noise the camera claims
  markerId @6 :Int32 = -1;    # the marker's id as detected; -1 when the source reports no id
                              # (simulated detections)
  corners @7 :List(Float64);  # [px] the marker's corners u0, v0, ..., u3, v3 in ArUco's order
                              # (top-left, top-right, bottom-right, bottom-left of the marker
                              # image); empty when not measured
}

# The robot entered or left a camera's floor footprint.
struct CameraEvent {
  header @0 :Common.Header;
  cameraId @1 :Int32;
  entered @2 :Bool;           # true = entered the view, false = left it
}

# The floor areas environment cameras see, in the map frame (true ones from a simulator, or
# estimated ones from a calibration), for display and scoring.
struct CameraFootprints {
  struct Footprint {
    cameraId @0 :Int32;
    xy @1 :List(Float64);        # polygon corners in the map frame: x0, y0, x1, y1, ... [m]
    calibrated @2 :Bool;         # true: estimated by a calibration; false: known (simulator,
                                 # survey)
  }
  header @0 :Common.Header;      # frameId = map
  cameras @1 :List(Footprint);
}

# One environment camera's floor-plane calibration in a SLAM submap
# (docs/algorithms.md#camera-network-calibration): camera_network_slam publishes it each time the
# camera is calibrated, or calibrated again after it went stale; the map assembler keeps the latest
# per camera and saves it with the map (docs/architecture.md#saved-slam-state).
struct CameraCalibration {
  header @0 :Common.Header;       # stamp of the visit's end it was calibrated from;
                                  # frameId = "submap_<submapId>", the floor points' frame
  cameraId @1 :Int32;
  submapId @2 :UInt32;            # the submap whose frame the floor points are in
  homography @3 :List(Float64);   # 9 values, row-major: floor [m] -> pixel [px],
                                  # [u v 1]^T ~ H [x y 1]^T, h22 = 1
  rmsPx @4 :Float64;              # [px] inliers' reprojection RMS after refinement
  coverage @5 :Float64;           # inlier pixels' convex hull area / image area, 0..1
  condition @6 :Float64;          # sigma_max / sigma_8 of the normalised DLT matrix
  pairs @7 :UInt32;               # (marker position, pixel) pairs it was estimated from
  inliers @8 :UInt32;             # of those, RANSAC's inliers
}
