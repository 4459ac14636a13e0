// brume — the table of image formats (internal).
//
// One row per format brume reads or writes without OpenImageIO: a sniff of
// the first bytes, a header read (size and channels, for the size and memory
// limits before any allocation), a read and a write, each a thin layer over
// the format's own library (libspng, libjpeg-turbo, libtiff, OpenEXR) or, for
// PFM and Radiance HDR, which no Debian library does better, brume's own.
// Every file a read's rows do not take -- a format not in the table, or a
// file of a row's format that the row leaves (a palette PNG, a CMYK JPEG, a
// multi-part OpenEXR) -- goes to the last, implicit row: OpenImageIO, loaded
// on first use (io/codec.hpp). Outputs are written by their rows only.
//
// read_image's readers, OutputSet::write, the --bits and --compression checks
// and the help texts iterate this table (image_io.cpp, outputs.cpp); adding a
// format is one file in src/io/formats/ and one line in formats.cpp.
//
// The contract of a row is pixels and the promised metadata, not another
// library's bytes: a file a row writes reads back, through brume and through
// OpenImageIO, to the values it was given (lossless forms) with its
// description, colour space and bit depth; a file OpenImageIO reads, the row
// reads to the same values (integer counts as the count times the float
// 1/255 or 1/65535, as OpenImageIO gives them). Tests: tests/io/.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "brume/image.hpp"
#include "brume/io.hpp"

namespace brume::io {

// The storage type of a file's values.
enum class Storage { u8, u16, f16, f32 };

// A --compression setting, parsed against the row's rules: "auto" (the
// row's default) or one of its names, with a level or -1.
struct Compression {
  std::string name = "auto";
  int level = -1;
  bool lossy = false;
};
struct CompressionRule {
  const char* name;
  int min_level, max_level;  // min > max: takes no level
  bool lossy;
};

struct Header {
  int width = 0, height = 0, channels = 0;
};

// What a reader is asked for.
struct ReadRequest {
  std::string path;
  // Called with (width, height, channels) after the header and before any
  // allocation; throws brume::Error for a file over the limits.
  std::function<void(int, int, int)> check;
  // Integer files: each value (the count times 1/(2^bits - 1)) is replaced by
  // map(value, bits), evaluated once per distinct count, so the result is
  // map's own bit for bit. Float files ignore it. Empty: no map.
  std::function<float(float, int)> map;
  bool with_alpha = false;  // keep an alpha channel (read_unassociated); else such files go on
  int threads = 1;          // the codec's threads (OpenEXR's pool)
  // OpenEXR: the value of the pixels of the display window outside the data
  // window, which the file does not hold (0: transparent black for colour;
  // NaN: unknown, for depth). A data window reaching outside the display
  // window is refused.
  float pad = 0.0f;
};

// What a reader gives back.
struct Decoded {
  Image img;
  FileInfo info;        // format, integer, bits, channel_names, description (path set by the caller)
  bool mapped = false;  // map was applied to the values
  int alpha = -1;       // the alpha channel (with_alpha)
  bool unassociated = false;
};

// What a writer is given: the values as stored.
struct WriteRequest {
  int width = 0, height = 0, channels = 0;
  Storage type = Storage::f32;
  const std::uint8_t* codes = nullptr;  // u8 files of sRGB colour: the codes (srgb_encode_8); else null
  const float* values = nullptr;        // the values (sRGB-encoded floats when srgb)
  bool srgb = false;                    // the values are sRGB-encoded (the file says so where it can)
  std::string description;              // ImageDescription (brume's record)
  Compression compression;
  int threads = 1;
  // OpenEXR: the channels' names and storage bits (16 half, 32 float) and
  // string attributes to carry (WriteOptions); null: the defaults.
  const std::vector<std::string>* channel_names = nullptr;
  const std::vector<int>* channel_bits = nullptr;
  const std::vector<std::pair<std::string, std::string>>* attributes = nullptr;
};

struct Format {
  const char* name;                     // FileInfo::format: OpenImageIO's name ("png", "openexr", "pnm")
  const char* title;                    // for messages ("PNG", "Radiance HDR")
  std::vector<std::string> extensions;  // lower case with the dot; the first is the one messages give
  std::vector<std::string> bits;        // what --bits takes
  const char* color_bits;               // --bits auto for colour
  const char* data_bits;                // --bits auto for data maps
  std::vector<CompressionRule> compressions;
  std::vector<int> channel_counts = {}; // what a file holds (empty: any count); others are refused
  bool holds_data;                      // stores any float exactly enough for data maps (not Radiance's RGBE)
  // The first bytes (at most 16) are this format's signature.
  bool (*sniff)(const unsigned char* head, std::size_t n);
  // Header and read: false when the row does not take this file (it goes on
  // to OpenImageIO, nothing changed); brume::Error for a damaged file the row
  // recognises (naming the file), and whatever check throws.
  bool (*header)(const std::string& path, Header& out);
  bool (*read)(const ReadRequest& request, Decoded& out);
  // What the request's values or size hold that the format cannot (its bit
  // depths and channel counts above are checked before it is called): the
  // error the user gets, or empty. Null: the row writes whatever passes them.
  std::string (*refuse)(const WriteRequest& request) = nullptr;
  // Writes `tmp`; false with *why (errno left as the failure set it).
  bool (*write)(const std::string& tmp, const WriteRequest& request, std::string* why);
  const char* auto_is;  // what --compression auto writes, for the help ("zip", "Sub filter, run-length deflate")
};

// The rows, in the order a read's sniff tries them.
const std::vector<const Format*>& formats();
// The row that writes files of this extension (".png"; lower case), or null.
const Format* format_of_extension(const std::string& ext);
// The row whose sniff takes the file's first bytes, or null (OpenImageIO's).
const Format* format_of_file(const std::string& path);

// The rows (each in src/io/formats/<name>.cpp).
const Format& pfm_format();
const Format& png_format();
const Format& jpeg_format();
const Format& tiff_format();
const Format& exr_format();
const Format& hdr_format();

// The integer-count conversion every integer row shares: n counts (8-bit
// bytes, or 16-bit in native byte order) to every step-th float of dst as
// the count times the float 1/255 or 1/65535, then map (once per distinct
// count). reset() once the header gives the bit depth.
class CountValues {
 public:
  void reset(int bits, const std::function<float(float, int)>& map);
  void convert(const unsigned char* src, float* dst, std::size_t n, std::size_t step = 1);

 private:
  int bits_ = 8;
  float k_ = 1.0f / 255.0f;
  std::function<float(float, int)> map_;
  std::vector<float> table_;
  std::vector<unsigned char> known_;
};

// A float to an integer count 0..max (255 or 65535): round half away from
// zero of v x max, clamped, NaN to 0 -- the rounding every integer writer
// uses (and OpenImageIO's).
inline unsigned to_count(float v, float max) {
  if (v != v) return 0;
  const float r = __builtin_roundf(v * max);
  return static_cast<unsigned>(r < 0.0f ? 0.0f : r > max ? max : r);
}

// Samples [at, at + n) of a write's values as an integer or float file
// stores them, to dst: 8-bit counts (the request's codes where it has them),
// 16-bit counts in host byte order, or 32-bit floats as they are.
void store_samples(const WriteRequest& r, std::size_t at, std::size_t n, unsigned char* dst);

// Threads the codecs may use: the IoThreads scope's count, else OpenMP's.
int io_threads();

// The row that read and the row that wrote this thread's last file ("oiio":
// OpenImageIO's module), for tests that a file took its row.
const char* last_reader();
const char* last_writer();
void note_reader(const char* row);
void note_writer(const char* row);

}  // namespace brume::io
