// Rows of the table over the former direct modules, each until its own
// file in src/io/formats/ replaces it (one section per format).
#include "io/formats/format.hpp"
#include "io/jpeg_direct.hpp"
#include "io/tiff_direct.hpp"

namespace brume::io {
namespace {
const std::vector<std::string> kYRGB[4] = {{}, {"Y"}, {}, {"R", "G", "B"}};
}

// ---- jpeg ----------------------------------------------------------------------
namespace {
bool jpeg_sniff(const unsigned char* h, std::size_t n) { return n >= 3 && h[0] == 0xff && h[1] == 0xd8 && h[2] == 0xff; }
bool jpeg_header(const std::string& path, Header& out) {
  detail::JpegInfo ji;
  if (!detail::read_jpeg_subset(path, nullptr, ji, [](int, int, int) {})) return false;
  out = {ji.width, ji.height, ji.channels};
  return true;
}
bool jpeg_read(const ReadRequest& r, Decoded& out) {
  detail::JpegInfo ji;
  if (!detail::read_jpeg_subset(r.path, &out.img, ji, r.check, r.map)) return false;
  out.info.format = "jpeg";
  out.info.integer = true;
  out.info.bits = 8;
  out.info.channel_names = kYRGB[ji.channels];
  out.info.description = ji.description;
  out.mapped = static_cast<bool>(r.map);
  return true;
}
std::string jpeg_refuse(const WriteRequest& r) {
  if (!detail::jpeg_subset_writable(r.channels, r.description.size())) return "not of the JPEG subset";
  return {};
}
bool jpeg_write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  return detail::write_jpeg_subset(tmp, r.width, r.height, r.channels, r.codes, r.values, r.srgb, r.description,
                                   r.compression.level >= 0 ? r.compression.level : 98, why);
}
}  // namespace

const Format& jpeg_format() {
  static const Format f{"jpeg", "JPEG", {".jpg", ".jpeg"}, {"8"}, "8", "8", {{"jpeg", 1, 100, true}},
                        {}, false, jpeg_sniff, jpeg_header, jpeg_read, jpeg_refuse, jpeg_write, "jpeg:98"};
  return f;
}

// ---- tiff ----------------------------------------------------------------------
namespace {
bool tiff_sniff(const unsigned char* h, std::size_t n) {
  return n >= 4 && ((h[0] == 'I' && h[1] == 'I' && (h[2] == 42 || h[2] == 43) && h[3] == 0) ||
                    (h[0] == 'M' && h[1] == 'M' && h[2] == 0 && (h[3] == 42 || h[3] == 43)));
}
bool tiff_header(const std::string& path, Header& out) {
  detail::TiffInfo ti;
  if (!detail::read_tiff_subset(path, nullptr, ti, [](int, int, int) {})) return false;
  out = {ti.width, ti.height, ti.channels};
  return true;
}
bool tiff_read(const ReadRequest& r, Decoded& out) {
  detail::TiffInfo ti;
  if (!detail::read_tiff_subset(r.path, &out.img, ti, r.check, r.map)) return false;
  out.info.format = "tiff";
  out.info.integer = !ti.floating;
  out.info.bits = ti.bits;
  out.info.channel_names = kYRGB[ti.channels];
  out.info.description = ti.description;
  out.mapped = !ti.floating && r.map;
  return true;
}
int tiff_bits(Storage t) { return t == Storage::u8 ? 8 : t == Storage::u16 ? 16 : t == Storage::f32 ? 32 : 0; }
std::string tiff_refuse(const WriteRequest& r) {
  if (!detail::tiff_subset_writable(r.channels, tiff_bits(r.type))) return "not of the TIFF subset";
  return {};
}
bool tiff_write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  const std::string name = r.compression.name;
  return detail::write_tiff_subset(tmp, r.width, r.height, r.channels, tiff_bits(r.type), r.codes, r.values, r.srgb,
                                   r.description, name, r.compression.level, std::min(r.threads, 64), why);
}
}  // namespace

const Format& tiff_format() {
  static const Format f{"tiff", "TIFF", {".tif", ".tiff"}, {"8", "16", "float"}, "16", "float",
                        {{"none", 1, 0, false}, {"lzw", 1, 0, false}, {"zip", 1, 9, false}, {"packbits", 1, 0, false}},
                        {}, true, tiff_sniff, tiff_header, tiff_read, tiff_refuse, tiff_write, "zip"};
  return f;
}

}  // namespace brume::io
