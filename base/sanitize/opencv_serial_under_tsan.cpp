// Linked into the executables of the ThreadSanitizer build only (TESSERA_SANITIZE_THREAD,
// scripts/tsan.sh): OpenCV's own parallel loops run serially there. OpenCV drives TBB through
// TBB's header templates compiled into libopencv_core, which is not built with TSan, so the waits
// that end its loops are invisible and every later use of the stack they ran on reads as a race
// with a TBB worker. Our own TBB loops are untouched, and checked.
#include <opencv2/core/utility.hpp>

namespace {
const bool kOpenCvSerial = [] {
  cv::setNumThreads(0);  // 0: run every function sequentially on the calling thread
  return true;
}();
}  // namespace
