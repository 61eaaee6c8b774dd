// distanceTransform: exact Euclidean distance transform of a flag grid.
#include <tessera/grid/distance_transform.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tessera::grid {

namespace {

// Squared distance transform of one line (Felzenszwalb and Huttenlocher's lower envelope of
// parabolas): d[q] = min_p (q - p)^2 + f[p]. v, z are scratch of n and n + 1 entries.
void distanceTransform1d(const double* f, int n, std::size_t stride, double* d, int* v, double* z) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  int k = 0;
  v[0] = 0;
  z[0] = -kInf;
  z[1] = kInf;
  for (int q = 1; q < n; ++q) {
    const double fq = f[q * stride] + double(q) * q;
    double s = 0;
    while (true) {  // z[0] = -inf ends the loop: every f is finite
      const int p = v[k];
      s = (fq - (f[p * stride] + double(p) * p)) / (2.0 * (q - p));
      if (s > z[k]) break;
      --k;
    }
    ++k;
    v[k] = q;
    z[k] = s;
    z[k + 1] = kInf;
  }
  k = 0;
  for (int q = 0; q < n; ++q) {
    while (z[k + 1] < q) ++k;
    const double dq = q - v[k];
    d[q * stride] = dq * dq + f[v[k] * stride];
  }
}

}  // namespace

std::vector<float> distanceTransform(const std::vector<std::uint8_t>& marked, int width,
                                     int height) {
  if (width < 0 || height < 0 ||
      marked.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw std::invalid_argument("distance transform: " + std::to_string(marked.size()) +
                                " flags for a " + std::to_string(width) + " x " +
                                std::to_string(height) + " grid");
  const int w = width, h = height;
  const std::size_t n = marked.size();
  if (n == 0) return {};
  // A large finite "no obstacle" keeps the parabola intersections free of inf - inf.
  const double kFar = 1e18;
  std::vector<double> f(n), g(n);
  for (std::size_t i = 0; i < n; ++i) f[i] = marked[i] ? 0.0 : kFar;
  const int longest = std::max(w, h);
  std::vector<int> v(static_cast<std::size_t>(longest));
  std::vector<double> z(static_cast<std::size_t>(longest) + 1);
  // Columns (along y) through a contiguous copy: strided access inside the envelope search
  // would miss the cache on every step of a wide map.
  std::vector<double> column(static_cast<std::size_t>(h)), column_out(static_cast<std::size_t>(h));
  for (int c = 0; c < w; ++c) {
    for (int r = 0; r < h; ++r)
      column[static_cast<std::size_t>(r)] = f[static_cast<std::size_t>(r) * w + c];
    distanceTransform1d(column.data(), h, 1, column_out.data(), v.data(), z.data());
    for (int r = 0; r < h; ++r)
      g[static_cast<std::size_t>(r) * w + c] = column_out[static_cast<std::size_t>(r)];
  }
  for (int r = 0; r < h; ++r) {  // then rows
    const std::size_t row = static_cast<std::size_t>(r) * static_cast<std::size_t>(w);
    distanceTransform1d(g.data() + row, w, 1, f.data() + row, v.data(), z.data());
  }
  std::vector<float> out(n);
  for (std::size_t i = 0; i < n; ++i)
    out[i] = f[i] >= kFar * 0.5 ? std::numeric_limits<float>::infinity()
                                : static_cast<float>(std::sqrt(f[i]));
  return out;
}

}  // namespace tessera::grid
