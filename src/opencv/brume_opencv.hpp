// brume — OpenCV imgproc, and calib3d (StereoSGBM) with features2d (ORB) for the stereo matching,
// included once with the warnings their headers raise under C++20 silenced (target brume_opencv:
// the library, the study, the tests and the benchmarks share it).
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
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
