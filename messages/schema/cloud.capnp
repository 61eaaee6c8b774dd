# Point clouds. Evolve by Cap'n Proto rules: add fields, never renumber. Bulk Data fields are
# allocated after every small field (see message.hpp: Loan size hint).
@0x8962ea283142fefc;

using Cxx = import "/capnp/c++.capnp";
$Cxx.namespace("tessera::msg");

using Common = import "common.capnp";

# A cloud of 3D points, e.g. a preview of a 3D map (the occupied voxels of an OctoMap).
struct PointCloud {
  header @0 :Common.Header;    # frameId = the frame the points are in (e.g. world, map)
  count @1 :UInt32;            # number of points
  voxelSize @2 :Float32;       # [m] edge of the voxel each point stands for; 0: raw points
  xyz @3 :Data;                # count * 3 float32, little-endian: x, y, z [m] per point
  rgb @4 :Data;                # count * 3 uint8 (r, g, b) per point; empty: no colour
}
