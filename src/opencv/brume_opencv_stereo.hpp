// brume — OpenCV's stereo matcher (calib3d) and features (features2d) with the
// warnings their headers raise under C++20 silenced, as brume_opencv.hpp does
// for imgproc; only src/depth/stereo.cpp and the stereo tests and bench include them.
#pragma once

#include "brume_opencv.hpp"

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-enum-enum-conversion"
#pragma GCC diagnostic ignored "-Wpedantic"
#endif
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
