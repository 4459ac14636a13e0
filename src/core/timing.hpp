// The wall time since a steady-clock instant, for --timing's lines and the
// records' "timing" blocks (internal).
#pragma once

#include <chrono>

namespace brume {

// Milliseconds since t0.
inline double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace brume
