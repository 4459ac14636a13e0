// brume — image containers.
//
// Every effect works on linear-light float images. An Image is a dense,
// row-major, channel-interleaved float buffer whose row 0 is the top of the
// picture (file formats that store rows bottom-up, such as PFM, are flipped on
// read). Unknown values (missing range, sky) are NaN.
//
// ImageView / ConstImageView are non-owning strided windows onto float pixels
// someone else owns (an Image, a numpy array, a renderer's mapped buffer), so
// they can be read or written without a copy. Element (x, y, c) lives at
// data[y * row_stride + x * pixel_stride + c]; both strides count FLOATS, not
// bytes (numpy: strides[0] / 4 and strides[1] / 4, or use from_byte_strides).
// A view of an Image has pixel_stride = channels and row_stride =
// width * channels; a view of the RGB of an RGBA buffer has channels = 3 and
// pixel_stride = 4. The view never outlives the pixels: it holds no ownership.
#pragma once

#include <algorithm>
#include <cassert>
#include <cstddef>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "brume/error.hpp"

namespace brume {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> data;  // size width*height*channels

  Image() = default;
  // w x h x c values, all `fill`. Buffers of 2 MB and more are given the
  // transparent-huge-page hint before the fill touches them (src/core/image.cpp:
  // ~12x fewer page-fault cycles on a VM); copies get it too. Moves keep the buffer.
  Image(int w, int h, int c, float fill = 0.0f);
  Image(const Image& o);
  Image& operator=(const Image& o);
  Image(Image&&) noexcept = default;
  Image& operator=(Image&&) noexcept = default;
  ~Image() = default;

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

// T is float (ImageView, writable) or const float (ConstImageView).
template <class T>
class BasicImageView {
  static_assert(std::is_same_v<std::remove_const_t<T>, float>, "brume views are of float pixels");

 public:
  BasicImageView() = default;

  // A window of width x height pixels of `channels` floats starting at data.
  // Throws brume::Error when the geometry is impossible: negative sizes, no
  // channels, a null pointer for a non-empty view, a pixel stride smaller than
  // the channels, or rows that would overlap. Strides are in floats.
  BasicImageView(T* data, int width, int height, int channels, std::ptrdiff_t row_stride,
                 std::ptrdiff_t pixel_stride)
      : data_(data), width_(width), height_(height), channels_(channels), row_stride_(row_stride),
        pixel_stride_(pixel_stride) {
    const std::string who = "image view " + std::to_string(width) + "x" + std::to_string(height) + "x" +
                            std::to_string(channels);
    if (width < 0 || height < 0)
      throw Error(who + ": negative width/height; use sizes >= 0");
    if (channels < 1) throw Error(who + ": channels must be >= 1");
    if (pixel_stride < channels)
      throw Error(who + ": pixel stride " + std::to_string(pixel_stride) + " floats is less than the " +
                  std::to_string(channels) +
                  " channels; pass the distance in floats between neighbouring pixels (numpy: strides[1] / 4)");
    const std::ptrdiff_t row_span = width > 0 ? (width - 1) * pixel_stride + channels : 0;
    if (height > 1 && row_stride < row_span)
      throw Error(who + ": row stride " + std::to_string(row_stride) + " floats is less than one row (" +
                  std::to_string(row_span) +
                  " floats), so rows would overlap; pass the distance in floats between row starts "
                  "(numpy: strides[0] / 4)");
    if (data == nullptr && width > 0 && height > 0)
      throw Error(who + ": null data pointer for a non-empty view; pass the first pixel's address");
  }

  // Same, with strides in bytes as numpy and most renderers report them; each
  // must be a whole number of floats.
  static BasicImageView from_byte_strides(T* data, int width, int height, int channels,
                                          std::ptrdiff_t row_stride_bytes, std::ptrdiff_t pixel_stride_bytes) {
    constexpr std::ptrdiff_t f = sizeof(float);
    if (row_stride_bytes % f != 0 || pixel_stride_bytes % f != 0)
      throw Error("image view: byte strides " + std::to_string(row_stride_bytes) + " (row) and " +
                  std::to_string(pixel_stride_bytes) + " (pixel) must be multiples of " + std::to_string(f) +
                  " (whole floats); make the array float32 and contiguous in each pixel");
    return BasicImageView(data, width, height, channels, row_stride_bytes / f, pixel_stride_bytes / f);
  }

  // The whole of an Image (dense: pixel stride = channels, row stride = width * channels).
  template <class I, class = std::enable_if_t<std::is_same_v<std::remove_const_t<I>, Image> &&
                                              (std::is_const_v<T> || !std::is_const_v<I>)>>
  BasicImageView(I& image)  // NOLINT: implicit, so an Image can be passed where a view is taken
      : BasicImageView(image.data.empty() ? nullptr : image.data.data(), image.width, image.height,
                       image.channels < 1 ? 1 : image.channels,
                       static_cast<std::ptrdiff_t>(image.width) * (image.channels < 1 ? 1 : image.channels),
                       image.channels < 1 ? 1 : image.channels) {
    if (image.data.size() != image.pixels() * static_cast<std::size_t>(image.channels))
      throw Error("image view of a " + image.size_string() + "x" + std::to_string(image.channels) +
                  " Image whose buffer holds " + std::to_string(image.data.size()) +
                  " floats; resize Image::data to width*height*channels");
  }

  // A writable view converts to a read-only one.
  template <class U, class = std::enable_if_t<std::is_const_v<T> && !std::is_const_v<U> &&
                                              std::is_same_v<std::remove_const_t<T>, U>>>
  BasicImageView(const BasicImageView<U>& v)  // NOLINT: implicit, as T* -> const T*
      : data_(v.data()), width_(v.width()), height_(v.height()), channels_(v.channels()),
        row_stride_(v.row_stride()), pixel_stride_(v.pixel_stride()) {}

  T* data() const { return data_; }
  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  std::ptrdiff_t row_stride() const { return row_stride_; }      // floats between row starts
  std::ptrdiff_t pixel_stride() const { return pixel_stride_; }  // floats between pixel starts
  std::size_t pixels() const { return static_cast<std::size_t>(width_) * height_; }
  bool empty() const { return width_ == 0 || height_ == 0; }
  // True when the pixels are one dense block laid out exactly as an Image's.
  bool contiguous() const {
    return pixel_stride_ == channels_ && (height_ <= 1 || row_stride_ == static_cast<std::ptrdiff_t>(width_) * channels_);
  }
  std::string size_string() const { return std::to_string(width_) + "x" + std::to_string(height_); }

  // Unchecked element access, like Image::at (asserts in debug builds only):
  // loops over a view must not pay a range check per sample.
  T& at(int x, int y, int c = 0) const {
    assert(x >= 0 && x < width_ && y >= 0 && y < height_ && c >= 0 && c < channels_);
    return data_[y * row_stride_ + x * pixel_stride_ + c];
  }
  // First float of row y; pixel x of that row starts at row(y) + x * pixel_stride().
  T* row(int y) const {
    assert(y >= 0 && y < height_);
    return data_ + y * row_stride_;
  }

  // The sub-rectangle [x, x+w) x [y, y+h), sharing the pixels. Throws
  // brume::Error when it does not lie inside this view.
  BasicImageView crop(int x, int y, int w, int h) const {
    if (x < 0 || y < 0 || w < 0 || h < 0 || x > width_ - w || y > height_ - h)
      throw Error("image view crop " + std::to_string(w) + "x" + std::to_string(h) + " at (" + std::to_string(x) +
                  ", " + std::to_string(y) + ") does not fit in the " + size_string() +
                  " view; use x, y >= 0, x + w <= " + std::to_string(width_) + ", y + h <= " +
                  std::to_string(height_));
    T* p = (w == 0 || h == 0) ? data_ : data_ + y * row_stride_ + x * pixel_stride_;
    return BasicImageView(p, w, h, channels_, row_stride_, pixel_stride_);
  }

  // Channels [first, first + count) of every pixel, sharing the pixels (e.g.
  // the RGB of an RGBA buffer). Throws brume::Error when out of range.
  BasicImageView channel_range(int first, int count) const {
    if (first < 0 || count < 1 || first > channels_ - count)
      throw Error("image view channels [" + std::to_string(first) + ", " + std::to_string(first + count) +
                  ") are not within the view's " + std::to_string(channels_) +
                  " channels; use 0 <= first, count >= 1, first + count <= " + std::to_string(channels_));
    return BasicImageView(data_ + first, width_, height_, count, row_stride_, pixel_stride_);
  }

  // A dense owning copy.
  Image to_image() const {
    Image out(width_, height_, channels_);
    for (int y = 0; y < height_; ++y) {
      const T* src = row(y);
      float* dst = out.row(y);
      for (int x = 0; x < width_; ++x)
        for (int c = 0; c < channels_; ++c) dst[x * channels_ + c] = src[x * pixel_stride_ + c];
    }
    return out;
  }

 private:
  T* data_ = nullptr;
  int width_ = 0, height_ = 0, channels_ = 1;
  std::ptrdiff_t row_stride_ = 0, pixel_stride_ = 1;
};

using ImageView = BasicImageView<float>;
using ConstImageView = BasicImageView<const float>;

// A dense owning copy of the pixels a view shows.
inline Image copy_of(ConstImageView v) { return v.to_image(); }

// Copies src into dst sample by sample (e.g. an effect's result back into a
// renderer's buffer). Throws brume::Error unless the sizes and channels agree.
// The two views must not overlap in memory unless they are the same view.
inline void copy(ConstImageView src, ImageView dst) {
  if (src.width() != dst.width() || src.height() != dst.height() || src.channels() != dst.channels())
    throw Error("image copy: source " + src.size_string() + "x" + std::to_string(src.channels()) +
                " and destination " + dst.size_string() + "x" + std::to_string(dst.channels()) +
                " differ; crop or choose channels so that the sizes and channel counts agree");
  for (int y = 0; y < src.height(); ++y)
    for (int x = 0; x < src.width(); ++x)
      for (int c = 0; c < src.channels(); ++c) dst.at(x, y, c) = src.at(x, y, c);
}

// A read-only DENSE image whose pixels someone else owns: an Image, or a
// caller's buffer laid out exactly as an Image's (a C-contiguous float32
// numpy array, wrapped by the Python module without a copy). It offers the
// Image members an effect's loops read (width, height, channels, data[i],
// data.data(), pixels(), at(), row()), so an effect written on `const Image&`
// takes a caller's buffer in place by changing only its signature, and its
// arithmetic -- hence its output bits -- is unchanged. An Image converts
// implicitly. Like a view, it owns nothing: never keep one past the pixels'
// life (binding it to a temporary Image outside a call dangles).
struct DenseImageRef {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::span<const float> data;  // width*height*channels floats

  DenseImageRef() = default;
  DenseImageRef(const Image& im)  // NOLINT: implicit, so an Image is passed where a ref is taken
      : width(im.width), height(im.height), channels(im.channels), data(im.data) {}
  // A view laid out as an Image (contiguous()); a strided view has no dense
  // form without a copy, so it is refused (copy_of it first).
  explicit DenseImageRef(ConstImageView v)
      : width(v.width()), height(v.height()), channels(v.channels()),
        data(v.data(), v.empty() ? 0 : v.pixels() * static_cast<std::size_t>(v.channels())) {
    if (!v.contiguous())
      throw Error("dense image of a " + v.size_string() + "x" + std::to_string(v.channels()) +
                  " view with pixel stride " + std::to_string(v.pixel_stride()) + " and row stride " +
                  std::to_string(v.row_stride()) + " floats: the pixels are not one dense block; pass copy_of(view)");
  }

  std::size_t pixels() const { return static_cast<std::size_t>(width) * height; }
  bool empty() const { return data.empty(); }
  const float* row(int y) const { return data.data() + static_cast<std::size_t>(y) * width * channels; }
  float at(int x, int y, int c = 0) const { return data[(static_cast<std::size_t>(y) * width + x) * channels + c]; }
  std::string size_string() const { return std::to_string(width) + "x" + std::to_string(height); }
  // The same pixels as a (dense) view, and as an owning copy.
  ConstImageView view() const {
    return empty() ? ConstImageView() : ConstImageView(data.data(), width, height, channels,
                                                      static_cast<std::ptrdiff_t>(width) * channels, channels);
  }
  Image to_image() const {
    Image out(width, height, channels);
    std::copy(data.begin(), data.end(), out.data.begin());
    return out;
  }
};

}  // namespace brume
