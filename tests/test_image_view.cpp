// Non-owning strided image views: addressing against the plain index formula
// on a bigger buffer, copies, and the geometry checks' error messages.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/image.hpp"
#include "test_util.hpp"

using namespace brume;
using namespace brume::test;

namespace {

// Value that names its own position, so a wrong stride shows up as a wrong value.
float tag(int x, int y, int c) { return static_cast<float>(10000 * y + 10 * x + c); }

// A 7x5 RGBA buffer padded to 9 pixels per row, as a renderer's pitched buffer.
struct Pitched {
  static constexpr int W = 7, H = 5, C = 4, PITCH_PX = 9;
  std::vector<float> buf = std::vector<float>(static_cast<std::size_t>(PITCH_PX) * H * C, -1.0f);
  Pitched() {
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        for (int c = 0; c < C; ++c) buf[(static_cast<std::size_t>(y) * PITCH_PX + x) * C + c] = tag(x, y, c);
  }
  ImageView view() { return ImageView(buf.data(), W, H, C, PITCH_PX * C, C); }
};


}  // namespace

TEST(ImageView, ViewOfImageIsDenseAndWritesThrough) {
  Image img(3, 2, 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 2; ++c) img.at(x, y, c) = tag(x, y, c);
  ImageView v(img);
  EXPECT_TRUE(v.contiguous());
  EXPECT_EQ(v.row_stride(), 6);
  EXPECT_EQ(v.pixel_stride(), 2);
  EXPECT_EQ(v.data(), img.data.data());
  EXPECT_EQ(v.at(2, 1, 1), tag(2, 1, 1));
  v.at(1, 1, 0) = 42.0f;
  EXPECT_EQ(img.at(1, 1, 0), 42.0f);  // no copy was made
  const ConstImageView cv = v;          // writable -> read-only
  EXPECT_EQ(cv.row(1), img.row(1));
  // Exact: to_image copies floats, no arithmetic.
  const Image back = copy_of(cv);
  EXPECT_EQ(back.width, 3);
  EXPECT_EQ(back.channels, 2);
  EXPECT_EQ(back.data, img.data);
}

TEST(ImageView, StridedSubRectangleOfABiggerBuffer) {
  Pitched p;
  const ImageView all = p.view();
  EXPECT_FALSE(all.contiguous());
  // A 3x2 window at (2, 1) and only its G and B channels.
  const ImageView win = all.crop(2, 1, 3, 2).channel_range(1, 2);
  ASSERT_EQ(win.width(), 3);
  ASSERT_EQ(win.height(), 2);
  ASSERT_EQ(win.channels(), 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 2; ++c) {
        EXPECT_EQ(win.at(x, y, c), tag(x + 2, y + 1, c + 1)) << x << "," << y << "," << c;
        EXPECT_EQ(win.row(y)[x * win.pixel_stride() + c], tag(x + 2, y + 1, c + 1));
      }
  const Image dense = win.to_image();
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 2; ++c) EXPECT_EQ(dense.at(x, y, c), tag(x + 2, y + 1, c + 1));
  // Writing back through copy() touches exactly the window's samples.
  Image ones(3, 2, 2, 1.0f);
  copy(ones, win);
  int changed = 0;
  for (int y = 0; y < Pitched::H; ++y)
    for (int x = 0; x < Pitched::PITCH_PX; ++x)
      for (int c = 0; c < Pitched::C; ++c) {
        const float v = p.buf[(static_cast<std::size_t>(y) * Pitched::PITCH_PX + x) * Pitched::C + c];
        const bool in = x >= 2 && x < 5 && y >= 1 && y < 3 && c >= 1 && c < 3;
        if (in) {
          EXPECT_EQ(v, 1.0f);
          ++changed;
        } else {
          EXPECT_EQ(v, x < Pitched::W ? tag(x, y, c) : -1.0f) << x << "," << y << "," << c;
        }
      }
  EXPECT_EQ(changed, 12);
}

TEST(ImageView, ByteStridesAsNumpyReportsThem) {
  Pitched p;
  const ConstImageView v = ConstImageView::from_byte_strides(p.buf.data(), Pitched::W, Pitched::H, 3,
                                                             Pitched::PITCH_PX * 4 * 4, 4 * 4);
  EXPECT_EQ(v.row_stride(), Pitched::PITCH_PX * 4);
  EXPECT_EQ(v.at(6, 4, 2), tag(6, 4, 2));
  const std::string m = error_of([&] { ConstImageView::from_byte_strides(p.buf.data(), 2, 2, 1, 10, 4); });
  EXPECT_NE(m.find("multiples of 4"), std::string::npos) << m;
}

TEST(ImageView, ImpossibleGeometryIsRefusedWithTheFix) {
  std::vector<float> b(64);
  std::string m = error_of([&] { ImageView(b.data(), 4, 2, 3, 12, 2); });
  EXPECT_NE(m.find("pixel stride 2"), std::string::npos) << m;
  EXPECT_NE(m.find("3 channels"), std::string::npos) << m;
  m = error_of([&] { ImageView(b.data(), 4, 2, 3, 10, 3); });  // one row needs 12 floats
  EXPECT_NE(m.find("row stride 10"), std::string::npos) << m;
  EXPECT_NE(m.find("overlap"), std::string::npos) << m;
  m = error_of([&] { ImageView(nullptr, 4, 2, 3, 12, 3); });
  EXPECT_NE(m.find("null data pointer"), std::string::npos) << m;
  m = error_of([&] { ImageView(b.data(), -1, 2, 3, 12, 3); });
  EXPECT_NE(m.find("negative"), std::string::npos) << m;
  m = error_of([&] { ImageView(b.data(), 4, 2, 0, 12, 3); });
  EXPECT_NE(m.find("channels must be >= 1"), std::string::npos) << m;
  // A single row may have any row stride; an empty view any pointer.
  EXPECT_NO_THROW(ImageView(b.data(), 4, 1, 3, 0, 3));
  EXPECT_NO_THROW(ImageView(nullptr, 0, 0, 1, 0, 1));
}

TEST(ImageView, CropAndChannelsOutsideTheViewAreRefused) {
  Pitched p;
  const ImageView v = p.view();
  std::string m = error_of([&] { v.crop(5, 0, 3, 1); });  // 5 + 3 > 7
  EXPECT_NE(m.find("crop 3x1 at (5, 0) does not fit in the 7x5 view"), std::string::npos) << m;
  EXPECT_NE(m.find("x + w <= 7"), std::string::npos) << m;
  m = error_of([&] { v.crop(0, -1, 1, 1); });
  EXPECT_NE(m.find("does not fit"), std::string::npos) << m;
  m = error_of([&] { v.channel_range(2, 3); });
  EXPECT_NE(m.find("channels [2, 5) are not within the view's 4 channels"), std::string::npos) << m;
  EXPECT_NO_THROW(v.crop(7, 5, 0, 0));  // an empty crop at the far corner is valid
  EXPECT_TRUE(v.crop(7, 5, 0, 0).empty());
}

TEST(ImageView, CopyRefusesMismatchedSizes) {
  Image a(4, 3, 3), b(4, 3, 4), c(3, 4, 3);
  std::string m = error_of([&] { copy(a, b); });
  EXPECT_NE(m.find("source 4x3x3 and destination 4x3x4 differ"), std::string::npos) << m;
  m = error_of([&] { copy(a, c); });
  EXPECT_NE(m.find("4x3x3"), std::string::npos) << m;
  EXPECT_NO_THROW(copy(a, ImageView(b).channel_range(0, 3)));
}

TEST(ImageView, ImageWithInconsistentBufferIsRefused) {
  Image bad(4, 4, 3);
  bad.data.resize(10);
  const std::string m = error_of([&] { ConstImageView v(bad); });
  EXPECT_NE(m.find("buffer holds 10 floats"), std::string::npos) << m;
}

// DenseImageRef: an Image's members over someone else's dense pixels (the
// Python module wraps a C-contiguous numpy array with it). Same addresses, same
// indexing as the Image it stands for; a strided view is refused, not copied.
TEST(DenseImageRef, ReadsTheCallersPixelsInPlaceAsAnImageWould) {
  Image im(7, 5, 3);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 7; ++x)
      for (int c = 0; c < 3; ++c) im.at(x, y, c) = tag(x, y, c);
  std::vector<float> caller = im.data;  // a foreign buffer with the same layout
  const DenseImageRef from_image(im);
  const DenseImageRef from_view(ConstImageView(caller.data(), 7, 5, 3, 21, 3));
  EXPECT_EQ(from_image.data.data(), im.data.data());
  EXPECT_EQ(from_view.data.data(), caller.data());  // no copy
  for (const DenseImageRef* r : {&from_image, &from_view}) {
    EXPECT_EQ(r->width, 7);
    EXPECT_EQ(r->height, 5);
    EXPECT_EQ(r->channels, 3);
    EXPECT_EQ(r->pixels(), 35u);
    for (int y = 0; y < 5; ++y)
      for (int x = 0; x < 7; ++x)
        for (int c = 0; c < 3; ++c) {
          EXPECT_EQ(r->at(x, y, c), tag(x, y, c));
          EXPECT_EQ(r->data[(static_cast<std::size_t>(y) * 7 + x) * 3 + c], tag(x, y, c));
          EXPECT_EQ(r->row(y)[x * 3 + c], tag(x, y, c));
        }
    EXPECT_EQ(r->to_image().data, im.data);
    EXPECT_EQ(r->view().data(), r->data.data());
    EXPECT_TRUE(r->view().contiguous());
  }
}

TEST(DenseImageRef, StridedViewIsRefusedWithTheFix) {
  Pitched p;
  const std::string m = error_of([&] { DenseImageRef r(ConstImageView(p.view()).channel_range(0, 3)); });
  EXPECT_NE(m.find("not one dense block"), std::string::npos) << m;
  EXPECT_NE(m.find("copy_of"), std::string::npos) << m;
  EXPECT_TRUE(DenseImageRef(ConstImageView()).empty());
}
