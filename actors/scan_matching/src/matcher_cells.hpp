// The scan matcher's inner-loop helpers: the grid capabilities it detects (hit points,
// occupancy bit rows), cell indices of beam endpoints (two poses at a time on SSE2) and bit
// scans. Internal to the scan-matching library, included by scan_matcher_impl.hpp. Metres in,
// cell indices and in-cell offsets [m] out.
#pragma once

#include <Eigen/Core>

#include <bit>
#include <concepts>
#include <cstdint>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tessera::scan_matching {

namespace detail {
/// Grids that can report, per cell, the mean position of the beam endpoints that hit it.
template <class Grid>
concept HitPointGrid = requires(const Grid& g, const Eigen::Vector2i& c) {
  { g.tracksHitPoints() } -> std::convertible_to<bool>;
  { g.hitPoint(c) } -> std::convertible_to<Eigen::Vector2d>;
};

/// Grids that can report a window's occupancy as bit rows (see the header comment).
template <class Grid>
concept OccupancyRowGrid = requires(const Grid& g, std::uint32_t* rows) {
  g.occupancyRows(0, 0, 1, 0.0f, rows);
};

/// floor(t) for the matcher's cell arithmetic, as an int. The SSE2 baseline has no rounding
/// instruction, and std::floor's generic sequence took a tenth of the matcher's time;
/// truncation and a branch-free correction (cells are negative as often as not) give the same
/// value. t is first clamped to ±2²⁹ cells, far beyond any map (27 000 km at 5 cm), so absurd
/// poses give far-away cells rather than overflow.
inline constexpr double kMaxCellIndex = 536870912.0;  // 2^29
inline int floorIndex(double t) {
  t = t < -kMaxCellIndex ? -kMaxCellIndex : t;
  t = t > kMaxCellIndex ? kMaxCellIndex : t;
  const int k = static_cast<int>(t);  // toward zero
  return k - static_cast<int>(t < static_cast<double>(k));
}

/// One beam endpoint e (base frame) at poses k < n, each given as translation (x, y) and the
/// cosine and sine of its heading: the cell of e in the map, relative to the cell whose centre
/// is `centre0` (the nearest lattice point: floorIndex(q + ½), q = (p − centre0)/res in cell
/// units, p = the pose applied to e), and e's offset from that cell's centre [m], in float.
/// The arrays hold an even number of entries at least n (on SSE2 two poses go at a time, with
/// the same operations in the same order as one at a time, hence the same values).
inline void endpointCells(int n, const double* x, const double* y, const double* cos_h,
                          const double* sin_h, double ex, double ey, const Eigen::Vector2d& centre0,
                          double res, int* cell_x, int* cell_y, float* ux, float* uy) {
  const double inv_res = 1.0 / res;
#if defined(__SSE2__)
  const __m128d vex = _mm_set1_pd(ex), vey = _mm_set1_pd(ey);
  const __m128d c0x = _mm_set1_pd(centre0.x()), c0y = _mm_set1_pd(centre0.y());
  const __m128d vinv = _mm_set1_pd(inv_res), vres = _mm_set1_pd(res), half = _mm_set1_pd(0.5);
  const __m128d lo = _mm_set1_pd(-kMaxCellIndex), hi = _mm_set1_pd(kMaxCellIndex);
  const __m128d one = _mm_set1_pd(1.0);
  auto floor2 = [&](__m128d t) {  // floorIndex() of both lanes, as doubles
    t = _mm_min_pd(_mm_max_pd(t, lo), hi);
    const __m128d k = _mm_cvtepi32_pd(_mm_cvttpd_epi32(t));
    return _mm_sub_pd(k, _mm_and_pd(_mm_cmplt_pd(t, k), one));
  };
  for (int k = 0; k < n; k += 2) {
    const __m128d c = _mm_loadu_pd(cos_h + k), s = _mm_loadu_pd(sin_h + k);
    // x + c·ex − s·ey and y + s·ex + c·ey, evaluated left to right as in scalar code.
    const __m128d px =
        _mm_sub_pd(_mm_add_pd(_mm_loadu_pd(x + k), _mm_mul_pd(c, vex)), _mm_mul_pd(s, vey));
    const __m128d py =
        _mm_add_pd(_mm_add_pd(_mm_loadu_pd(y + k), _mm_mul_pd(s, vex)), _mm_mul_pd(c, vey));
    const __m128d qx = _mm_mul_pd(_mm_sub_pd(px, c0x), vinv);
    const __m128d qy = _mm_mul_pd(_mm_sub_pd(py, c0y), vinv);
    const __m128d fx = floor2(_mm_add_pd(qx, half)), fy = floor2(_mm_add_pd(qy, half));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(cell_x + k), _mm_cvttpd_epi32(fx));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(cell_y + k), _mm_cvttpd_epi32(fy));
    _mm_storel_pi(reinterpret_cast<__m64*>(ux + k),
                  _mm_cvtpd_ps(_mm_mul_pd(_mm_sub_pd(qx, fx), vres)));
    _mm_storel_pi(reinterpret_cast<__m64*>(uy + k),
                  _mm_cvtpd_ps(_mm_mul_pd(_mm_sub_pd(qy, fy), vres)));
  }
#else
  for (int k = 0; k < n; ++k) {
    const double c = cos_h[k], s = sin_h[k];
    const double px = x[k] + c * ex - s * ey, py = y[k] + s * ex + c * ey;
    const double qx = (px - centre0.x()) * inv_res, qy = (py - centre0.y()) * inv_res;
    cell_x[k] = floorIndex(qx + 0.5);
    cell_y[k] = floorIndex(qy + 0.5);
    ux[k] = static_cast<float>((qx - cell_x[k]) * res);
    uy[k] = static_cast<float>((qy - cell_y[k]) * res);
  }
#endif
}

/// Index of the lowest / highest set bit of a non-zero word: one instruction, where
/// std::countr_zero / countl_zero add a test for zero on the x86-64 baseline.
inline int lowestBit(std::uint32_t nonzero) {
#if defined(__GNUC__)
  return __builtin_ctz(nonzero);
#else
  return std::countr_zero(nonzero);
#endif
}
inline int highestBit(std::uint32_t nonzero) {
#if defined(__GNUC__)
  return 31 - __builtin_clz(nonzero);
#else
  return 31 - std::countl_zero(nonzero);
#endif
}
}  // namespace detail

}  // namespace tessera::scan_matching
