// brume study — the sky fit's scatter plot (measured against model luminance).
#pragma once

#include <nlohmann/json.hpp>

#include "brume/image.hpp"

namespace brume::study {

// The samples of a `brume sky fit` JSON as a log-log scatter, inliers blue,
// RANSAC outliers red, with the line measured = model; linear RGB (store as
// 8-bit sRGB PNG).
Image sky_fit_scatter(const nlohmann::json& fit);

}  // namespace brume::study
