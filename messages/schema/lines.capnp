# Line-feature maps (docs/algorithms.md#line-ekf-slam): infinite lines in polar form with the extent seen so far.
# Evolve by Cap'n Proto rules: add fields, never renumber.
@0xd4b5f8c0b177e472;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# One line: every point p on it satisfies p . (cos phi, sin phi) = r.
struct LineFeature {
  id @0 :Int64;
  r @1 :Float64;                 # [m] >= 0, from the frame origin
  phi @2 :Float64;               # [rad] direction of the normal, (-pi, pi]
  covariance @3 :List(Float64);  # 4 values over (r, phi), row-major; empty = unknown
  x0 @4 :Float64;                # [m] end points of the extent seen so far
  y0 @5 :Float64;
  x1 @6 :Float64;
  y1 @7 :Float64;
  observations @8 :UInt32;       # times the line was matched (or fused)
}

# A line map, e.g. the state of a line-feature SLAM filter.
struct LineMap {
  header @0 :Common.Header;      # frameId = map
  lines @1 :List(LineFeature);
  tentative @2 :UInt32;          # candidate lines not (yet) in the map
}
