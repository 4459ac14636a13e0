// brume — image containers.
//
// Every effect works on linear-light float images. An Image is a dense,
// row-major, channel-interleaved float buffer whose row 0 is the top of the
// picture (file formats that store rows bottom-up, such as PFM, are flipped on
// read). Unknown values (missing range, sky) are NaN.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace brume {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> data;  // size width*height*channels

  Image() = default;
  Image(int w, int h, int c, float fill = 0.0f)
      : width(w), height(h), channels(c),
        data(static_cast<std::size_t>(w) * h * c, fill) {}

  std::size_t pixels() const { return static_cast<std::size_t>(width) * height; }
  bool empty() const { return data.empty(); }
  float* row(int y) { return data.data() + static_cast<std::size_t>(y) * width * channels; }
  const float* row(int y) const {
    return data.data() + static_cast<std::size_t>(y) * width * channels;
  }
  float& at(int x, int y, int c = 0) {
    return data[(static_cast<std::size_t>(y) * width + x) * channels + c];
  }
  float at(int x, int y, int c = 0) const {
    return data[(static_cast<std::size_t>(y) * width + x) * channels + c];
  }
  std::string size_string() const {
    return std::to_string(width) + "x" + std::to_string(height);
  }
};

}  // namespace brume
