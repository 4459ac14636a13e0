// Rows of the table over the former direct modules, each until its own
// file in src/io/formats/ replaces it (one section per format).
#include "io/exr_direct.hpp"
#include "io/formats/format.hpp"

namespace brume::io {
// ---- exr -----------------------------------------------------------------------
namespace {
bool exr_sniff(const unsigned char* h, std::size_t n) {
  return n >= 4 && h[0] == 0x76 && h[1] == 0x2f && h[2] == 0x31 && h[3] == 0x01;
}
bool exr_header(const std::string& path, Header& out) {
  detail::ExrInfo ei;
  if (!detail::read_exr_subset(path, nullptr, ei, [](int, int, int) {}, 0)) return false;
  out = {ei.width, ei.height, ei.channels};
  return true;
}
bool exr_read(const ReadRequest& r, Decoded& out) {
  detail::ExrInfo ei;
  if (r.with_alpha && (!detail::read_exr_subset(r.path, nullptr, ei, [](int, int, int) {}, 0) || ei.channels < 3))
    return false;
  if (!detail::read_exr_subset(r.path, &out.img, ei, r.check, std::min(r.threads, 64))) return false;
  out.info.format = "openexr";
  out.info.integer = false;
  out.info.bits = ei.bits;
  out.info.channel_names = std::move(ei.channel_names);
  out.info.description = std::move(ei.description);
  out.alpha = ei.channels == 4 ? 3 : -1;
  return true;
}
std::string exr_refuse(const WriteRequest& r) {
  if (r.compression.level >= 0 || !detail::exr_subset_writable(r.channels, !r.srgb, r.compression.name))
    return "not of the OpenEXR subset";
  return {};
}
bool exr_write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  return detail::write_exr_subset(tmp, r.width, r.height, r.channels, r.type == Storage::f16, r.values,
                                  r.compression.name, r.description, std::min(r.threads, 64), why);
}
}  // namespace

const Format& exr_format() {
  static const Format f{"openexr", "OpenEXR", {".exr"}, {"half", "float"}, "float", "float",
                        {{"none", 1, 0, false}, {"rle", 1, 0, false}, {"zip", 1, 9, false}, {"zips", 1, 9, false},
                         {"piz", 1, 0, false}, {"pxr24", 1, 0, true}, {"b44", 1, 0, true}, {"b44a", 1, 0, true},
                         {"dwaa", 1, 1000, true}, {"dwab", 1, 1000, true}},
                        {}, true, exr_sniff, exr_header, exr_read, exr_refuse, exr_write, "zip"};
  return f;
}

}  // namespace brume::io
