// The image codecs (OpenImageIO), loaded on first use.
//
// Debian's OpenImageIO links 260 shared libraries (ffmpeg, GDAL, DCMTK,
// libheif, OpenVDB, ...). Loading and relocating them is ~0.4 s of every
// process that links it -- 20x the rest of brume's start-up (docs/performance.md:
// `brume --version` 0.42 s linked, 0.02 s without) and more than a whole
// diffusion. So libbrume does not link OpenImageIO: the few calls it makes
// live in a module, brume_codec.so (src/io/oiio/codec_oiio.cpp), that brume
// dlopens the first time a file needs it: the files no row of the table of
// formats takes (src/io/formats/format.hpp). A run whose files the rows
// take, every run that fails its checks, `--help` and `--version` never
// load it.
//
// Where the module is looked for: $BRUME_CODEC_MODULE (a path) when set,
// and only there -- for a relocated install. Otherwise, first found wins
// (each must be the module of this very build, checked by its tag, else the
// next is tried):
//   1. next to the executable or shared object that holds libbrume
//      (the Python package installs it beside _brume.so);
//   2. ../lib/brume/ from there (an installed bin/brume);
//   3. the install path and the build path this libbrume was configured with.
// When none loads, the error names every path tried and why.
//
// The interface is C++ (same compiler, same build) but throws nothing across
// the boundary: failures come back as false/null plus a message.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace brume::codec {

struct InputSpec {
  int width = 0, height = 0, channels = 0;
  bool floating = false;     // the stored values are floating point
  int container_bits = 0;    // bits of the stored type (8, 16, 32, ...)
  int bits_per_sample = 0;   // oiio:BitsPerSample (0: not given)
  std::vector<std::string> channel_names;
  std::string description;   // ImageDescription
  std::string format;        // OpenImageIO's format name ("png", "openexr", ...)
  int alpha_channel = -1;
  bool unassociated_alpha = false;  // oiio:UnassociatedAlpha
};

class Input {
 public:
  virtual ~Input() = default;
  virtual const InputSpec& spec() const = 0;
  // Every channel of the first subimage as float, in `out` (w * h * c values).
  virtual bool read_float(float* out) = 0;
  virtual std::string error() = 0;
  virtual void close() = 0;
};

// The module's entry points. `tag` identifies the build (kCodecTag).
struct Api {
  const char* tag;
  // null and *err set when the file cannot be opened (err may be empty).
  std::unique_ptr<Input> (*open_input)(const std::string& path, bool unassociated_alpha, std::string* err);
};

// The tag both sides are built with (interface revision, brume's version,
// the compiler's): the module is used only if it matches.
inline constexpr const char* kCodecTag = "brume-codec-3 " BRUME_VERSION " " __VERSION__;

// The module's entry symbol: extern "C" const Api* brume_codec_api();
inline constexpr const char* kEntrySymbol = "brume_codec_api";

// The loaded module (loaded on the first call; thread-safe). Throws
// brume::Error naming every path tried when it cannot be loaded; `why` says
// what needed it ("reading 'x.png'").
const Api& api(const std::string& why);

}  // namespace brume::codec
