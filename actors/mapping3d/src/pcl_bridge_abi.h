/* The C ABI of libtessera_pcl_bridge.so, the module that holds every use of PCL in Tessera
 * (pcl_bridge_module.cpp implements it, pcl_bridge.cpp loads it with dlopen on first use).
 * Only plain arrays, sizes and C strings cross it, so neither side depends on the other's C++
 * types, standard library or compiler flags.
 *
 * Ownership: arrays passed in belong to the caller and are only read during the call; arrays a
 * function hands to a sink belong to the module and are valid only while the sink runs (the sink
 * copies them). A point cloud is `count` points as xyz[3 * i + 0..2] (float, metres) and, when
 * `rgb` is not null, rgb[3 * i + 0..2] (R, G, B).
 *
 * Every function returns TESSERA_PCL_OK or one of the negative codes below; for
 * TESSERA_PCL_EXCEPTION the message is written, NUL-terminated and truncated to fit, to
 * `error` (`error_size` bytes; may be null). No C++ exception leaves the module. */
#ifndef TESSERA_MAPPING3D_PCL_BRIDGE_ABI_H
#define TESSERA_MAPPING3D_PCL_BRIDGE_ABI_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped on any change to the functions below: the loader refuses a module of another
 * version (a stale copy left in ../lib, say). */
#define TESSERA_PCL_BRIDGE_ABI_VERSION 1

#define TESSERA_PCL_OK 0
/* PCL returned a failure code (it prints the reason to stderr itself). */
#define TESSERA_PCL_FAILED (-1)
/* PCL (or an allocation) threw: the message is in `error`. */
#define TESSERA_PCL_EXCEPTION (-2)
/* The caller's sink returned non-zero: the caller knows why. */
#define TESSERA_PCL_SINK_FAILED (-3)

/* Receives a cloud the module made (see Ownership above); returns 0, or non-zero to fail the
 * call with TESSERA_PCL_SINK_FAILED. */
typedef int (*tessera_pcl_sink)(void* context, const float* xyz, const uint8_t* rgb, size_t count);

int tessera_pcl_bridge_abi_version(void);

/* pcl::VoxelGrid at a cubic `leaf` [m] (PointXYZRGB with colours averaged when rgb is given,
 * PointXYZ otherwise); the filtered cloud goes to `sink`. */
int tessera_pcl_voxel_filter(const float* xyz, const uint8_t* rgb, size_t count, float leaf,
                             tessera_pcl_sink sink, void* sink_context, char* error,
                             size_t error_size);

/* pcl::io::savePCDFileBinary / pcl::PLYWriter (binary, no camera element) to `path`. */
int tessera_pcl_save_pcd_binary(const char* path, const float* xyz, const uint8_t* rgb,
                                size_t count, char* error, size_t error_size);
int tessera_pcl_save_ply_binary(const char* path, const float* xyz, const uint8_t* rgb,
                                size_t count, char* error, size_t error_size);

/* pcl::io::loadPCDFile / loadPLYFile; the cloud (with colours when the file has an rgb or rgba
 * field) goes to `sink`. */
int tessera_pcl_load_pcd(const char* path, tessera_pcl_sink sink, void* sink_context, char* error,
                         size_t error_size);
int tessera_pcl_load_ply(const char* path, tessera_pcl_sink sink, void* sink_context, char* error,
                         size_t error_size);

#ifdef __cplusplus
}
#endif

#endif /* TESSERA_MAPPING3D_PCL_BRIDGE_ABI_H */
