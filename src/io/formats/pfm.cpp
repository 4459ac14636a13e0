// PFM (Middlebury's and Debevec's portable float map), read and written by
// brume itself: no Debian library reads it better, and OpenImageIO's PNM
// reader, on open, copies the whole file into a zero-filled buffer of its
// own before the pixels are asked for (two passes over a 21.5 MB map).
//
// The form: magic "PF" (RGB) or "Pf" (grey), then width, height (decimal
// digits) and scale (a plain decimal number), separated by spaces, tabs or
// line ends, then exactly one whitespace byte and width x height x channels
// 32-bit floats, rows from the bottom of the picture up, little-endian for a
// negative scale, big-endian for a positive one; the values are the stored
// floats times |scale| (in float). A file outside that strict form -- a
// comment, an odd number, a short file -- goes to OpenImageIO, whose reading
// and messages stand. FileInfo as OpenImageIO gives a PFM: format "pnm",
// 32-bit float, channels R G B or Y. brume writes scale -1.0
// (little-endian). Tests: IO.Pfm* (tests/io/test_io.cpp).
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>

#include "io/formats/format.hpp"

namespace brume::io {
namespace pfm_row {
namespace fs = std::filesystem;

struct PfmHeader {
  int width = 0, height = 0, channels = 0;
  double scale = 0.0;
  std::size_t offset = 0;  // where the pixels start
};

bool pfm_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

bool sniff(const unsigned char* h, std::size_t n) {
  return n >= 3 && h[0] == 'P' && (h[1] == 'F' || h[1] == 'f') && pfm_space(static_cast<char>(h[2]));
}

// The header when the file is of the strict form and long enough.
std::optional<PfmHeader> parse_header(const std::string& path, std::ifstream& f) {
  char head[256];
  f.read(head, sizeof head);
  const auto got = static_cast<std::size_t>(f.gcount());
  if (!sniff(reinterpret_cast<const unsigned char*>(head), got)) return std::nullopt;
  PfmHeader h;
  h.channels = head[1] == 'F' ? 3 : 1;
  std::size_t i = 2;
  std::string tok[3];
  for (std::string& t : tok) {
    while (i < got && pfm_space(head[i])) ++i;
    while (i < got && !pfm_space(head[i])) t += head[i++];
    if (t.empty() || i >= got) return std::nullopt;
  }
  h.offset = i + 1;  // the single whitespace byte that ends the header
  for (int k = 0; k < 2; ++k) {
    const std::string& t = tok[k];
    if (t.size() > 9 || t.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
    const long v = std::strtol(t.c_str(), nullptr, 10);
    if (v < 1) return std::nullopt;
    (k == 0 ? h.width : h.height) = static_cast<int>(v);
  }
  // [-]digits[.digits][(e|E)[+|-]digits]: no inf, nan, hex or leading '+'.
  const std::string& t = tok[2];
  std::size_t j = t[0] == '-' ? 1 : 0;
  const std::size_t int_start = j;
  while (j < t.size() && std::isdigit(static_cast<unsigned char>(t[j]))) ++j;
  if (j == int_start) return std::nullopt;
  if (j < t.size() && t[j] == '.') {
    ++j;
    while (j < t.size() && std::isdigit(static_cast<unsigned char>(t[j]))) ++j;
  }
  if (j < t.size() && (t[j] == 'e' || t[j] == 'E')) {
    ++j;
    if (j < t.size() && (t[j] == '+' || t[j] == '-')) ++j;
    const std::size_t e0 = j;
    while (j < t.size() && std::isdigit(static_cast<unsigned char>(t[j]))) ++j;
    if (j == e0) return std::nullopt;
  }
  if (j != t.size()) return std::nullopt;
  h.scale = std::strtod(t.c_str(), nullptr);
  if (h.scale == 0.0 || !std::isfinite(h.scale)) return std::nullopt;
  // A short file goes to OpenImageIO, which says what is wrong with it.
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(path, ec);
  const std::uint64_t px = static_cast<std::uint64_t>(h.width) * static_cast<std::uint64_t>(h.height);
  if (ec || size < h.offset || (size - h.offset) / 4 / static_cast<std::uint64_t>(h.channels) < px)
    return std::nullopt;
  return h;
}

bool header(const std::string& path, Header& out) {
  std::ifstream f(path, std::ios::binary);
  const std::optional<PfmHeader> h = f ? parse_header(path, f) : std::nullopt;
  if (!h) return false;
  out = {h->width, h->height, h->channels};
  return true;
}

bool read(const ReadRequest& r, Decoded& out) {
  std::ifstream f(r.path, std::ios::binary);
  const std::optional<PfmHeader> ph = f ? parse_header(r.path, f) : std::nullopt;
  if (!ph) return false;
  r.check(ph->width, ph->height, ph->channels);
  Image img(ph->width, ph->height, ph->channels);
  const std::size_t row = static_cast<std::size_t>(ph->width) * static_cast<std::size_t>(ph->channels);
  f.clear();
  f.seekg(static_cast<std::streamoff>(ph->offset));
  for (long y = ph->height - 1; y >= 0; --y) {
    f.read(reinterpret_cast<char*>(img.data.data() + static_cast<std::size_t>(y) * row),
           static_cast<std::streamsize>(row * 4));
    if (!f) return false;
  }
  static_assert(sizeof(float) == 4);
  const std::uint32_t probe = 1;
  const bool host_little = *reinterpret_cast<const unsigned char*>(&probe) == 1;
  if ((ph->scale < 0.0) != host_little)
    for (float& v : img.data) {
      std::uint32_t b;
      std::memcpy(&b, &v, 4);
      b = __builtin_bswap32(b);
      std::memcpy(&v, &b, 4);
    }
  const float k = static_cast<float>(std::fabs(ph->scale));
  if (k != 1.0f)
    for (float& v : img.data) v *= k;
  out.img = std::move(img);
  out.info.format = "pnm";  // OpenImageIO's name for the format
  out.info.integer = false;
  out.info.bits = 32;
  out.info.channel_names = ph->channels == 3 ? std::vector<std::string>{"R", "G", "B"} : std::vector<std::string>{"Y"};
  return true;
}

bool write(const std::string& tmp, const WriteRequest& r, std::string*) {
  std::ofstream f(tmp, std::ios::binary);
  f << (r.channels == 1 ? "Pf" : "PF") << "\n" << r.width << " " << r.height << "\n-1.0\n";
  const std::uint32_t probe = 1;
  const bool little = *reinterpret_cast<const unsigned char*>(&probe) == 1;
  const std::size_t n = static_cast<std::size_t>(r.width) * static_cast<std::size_t>(r.channels);
  std::vector<float> row(n);
  for (int y = r.height - 1; y >= 0; --y) {
    std::memcpy(row.data(), r.values + static_cast<std::size_t>(y) * n, n * 4);
    if (!little)
      for (float& v : row) {
        std::uint32_t b;
        std::memcpy(&b, &v, 4);
        b = __builtin_bswap32(b);
        std::memcpy(&v, &b, 4);
      }
    f.write(reinterpret_cast<const char*>(row.data()), static_cast<std::streamsize>(n * 4));
  }
  f.close();
  return static_cast<bool>(f);
}
}  // namespace pfm_row

const Format& pfm_format() {
  using namespace pfm_row;
  static const Format f{.name = "pnm", .title = "PFM", .extensions = {".pfm"}, .bits = {"float"}, .color_bits = "float",
                        .data_bits = "float", .compressions = {{"none", 1, 0, false}}, .channel_counts = {1, 3},
                        .holds_data = true, .sniff = sniff, .header = header, .read = read, .write = write,
                        .auto_is = "none"};
  return f;
}

}  // namespace brume::io
