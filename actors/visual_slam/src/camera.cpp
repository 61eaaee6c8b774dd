// PinholeCamera::validate(): rejects intrinsics that would turn every back-projection into NaN.
#include <tessera/visual_slam/camera.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::visual_slam {

void PinholeCamera::validate() const {
  const auto bad = [](const char* field, double value) {
    throw std::invalid_argument(std::string("camera intrinsics: ") + field + " = " +
                                std::to_string(value) + " is not valid");
  };
  if (!std::isfinite(fx) || fx <= 0) bad("fx", fx);
  if (!std::isfinite(fy) || fy <= 0) bad("fy", fy);
  if (!std::isfinite(cx)) bad("cx", cx);
  if (!std::isfinite(cy)) bad("cy", cy);
  if (width <= 0) bad("width", width);
  if (height <= 0) bad("height", height);
}

}  // namespace tessera::visual_slam
