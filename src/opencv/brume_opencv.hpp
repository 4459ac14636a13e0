// brume — OpenCV imgproc, included once with the warnings its headers raise under C++20 silenced
// (target brume_opencv: the library, the study and the benchmarks share it).
#pragma once

// OpenCV 4.x headers mix enum types in arithmetic (deprecated in C++20) and
// use C11 _Atomic (clang -Wpedantic).
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-enum-enum-conversion"
#pragma GCC diagnostic ignored "-Wpedantic"
#endif
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
