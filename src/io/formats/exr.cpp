// OpenEXR, read and written through OpenEXR 3.1's public API (Imf::InputFile
// and Imf::OutputFile with a FrameBuffer of slices over brume's interleaved
// image; OpenEXR converts half to float on reading and (de)compresses line
// blocks on its global thread pool; scanline files stored none, rle, zips or
// zip are read through its C core instead, read_core below).
//  - read: a single-part image file, scanline or tiled (deep and multi-part
//    files go to OpenImageIO), any data window (its pixels, as OpenImageIO's
//    read_image gives them), every channel of one pixel type, half or float,
//    not subsampled, and either one channel (any name) or R G B or R G B A --
//    given in the order OpenImageIO gives those sets (R, G, B, A first; the
//    file stores channels sorted by name). Other sets, which OpenImageIO
//    orders by rules of its own, go to it, as does one channel when alpha is
//    asked for (OpenImageIO calls a lone "A" alpha). FileInfo as OpenImageIO
//    gives it: "openexr", 16 bits (half) or 32 (float), the channel names,
//    the "comments" attribute (OpenImageIO's ImageDescription). Every open
//    first runs the attribute guard (check_exr_attributes, below).
//  - write: any channel count, named as OpenImageIO names them (1: Y; else R,
//    G, B, A, channel4, channel5, ...), half or float, the compression and
//    level asked for (auto: zip), the description as "comments", an sRGB
//    request marked with the string attribute "oiio:ColorSpace" = "sRGB"
//    (OpenImageIO reads it back; linear files carry nothing, which
//    OpenImageIO reports as linear). The file goes through brume's own
//    stream, so a failed write or close (ENOSPC, EFBIG) is an error with its
//    errno rather than a file OpenEXR's destructor could not finish.
// Tests: IO.Exr* (tests/io/test_exr.cpp).
#include "io/formats/exr.hpp"

#include <Imath/half.h>
#include <OpenEXR/Iex.h>
#include <OpenEXR/IexThrowErrnoExc.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfInputPart.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfPartType.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStdIO.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVersion.h>
#include <OpenEXR/openexr.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>

#include "brume/error.hpp"
#include "core/schedule.hpp"
#include "io/formats/format.hpp"

namespace brume::io {

void check_exr_attributes(const std::string& path) {
  // Only the first MB is read (it holds any real header's attributes but a
  // large preview); the scan stops at its end and leaves the rest to OpenEXR.
  std::error_code ec;
  const std::uintmax_t total = std::filesystem::file_size(path, ec);
  if (ec || total < 8) return;
  std::ifstream f(path, std::ios::binary);
  std::vector<char> b(8);
  if (!f.read(b.data(), 8) || !Imf::isImfMagic(b.data())) return;  // not OpenEXR: nothing more is read
  b.resize(static_cast<std::size_t>(std::min<std::uintmax_t>(total, 1u << 20)));
  if (!f.read(b.data() + 8, static_cast<std::streamsize>(b.size() - 8))) return;
  const std::size_t n = b.size();
  const bool multipart = (static_cast<unsigned char>(b[5]) & 0x10) != 0;  // version bit 12
  std::size_t i = 8;
  auto cstring = [&](std::string& out) {
    const std::size_t start = i;
    while (i < n && b[i] != '\0' && i - start < 256) ++i;
    if (i >= n || b[i] != '\0') return false;
    out.assign(&b[start], i - start);
    ++i;
    return true;
  };
  for (;;) {  // headers: attributes of name, type, int32 size, bytes
    std::string name, type;
    if (!cstring(name)) return;
    if (name.empty()) {  // end of this header; a multi-part file ends its list with an empty header
      if (!multipart || i >= n || b[i] == '\0') return;
      continue;
    }
    if (!cstring(type) || i + 4 > n) return;
    std::int32_t size = 0;
    std::memcpy(&size, &b[i], 4);  // little-endian, as the hosts brume builds for (x86-64, arm64)
    i += 4;
    if (size < 0 || static_cast<std::uintmax_t>(size) > total - i)
      throw Error("cannot read '" + path + "': a corrupt OpenEXR header (attribute '" + name + "' declares " +
                  std::to_string(size) + " bytes, but " + std::to_string(total - i) + " remain in the file)");
    i += static_cast<std::size_t>(size);
  }
}

// The row's parts, in a namespace of their own: a unity build joins the rows'
// files into one unit.
namespace exr_row {
namespace {

// OpenEXR (de)compresses on its global pool, which only grows here: another
// thread's read or write, or OpenImageIO (which sets the pool too), may be
// using it. 0 or 1 thread: the calling thread does the work (no pool hand-off).
// Returns the thread count to give a file.
int ensure_pool(int threads) {
  threads = std::min(threads, 64);
  if (threads <= 1) return 0;
  static std::mutex m;
  std::lock_guard<std::mutex> lock(m);
  if (Imf::globalThreadCount() < threads) Imf::setGlobalThreadCount(threads);
  return threads;
}

bool sniff(const unsigned char* head, std::size_t n) {
  return n >= 4 && head[0] == 0x76 && head[1] == 0x2f && head[2] == 0x31 && head[3] == 0x01;
}

// The channel order OpenImageIO gives, for the sets the row takes; empty for
// any other set (left to OpenImageIO).
std::vector<std::string> channel_order(const Imf::ChannelList& list, Imf::PixelType& type) {
  std::vector<std::string> names;
  bool first = true;
  for (auto it = list.begin(); it != list.end(); ++it) {
    const Imf::Channel& c = it.channel();
    if (c.xSampling != 1 || c.ySampling != 1) return {};
    if (c.type != Imf::HALF && c.type != Imf::FLOAT) return {};
    if (!first && c.type != type) return {};
    type = c.type;
    first = false;
    names.emplace_back(it.name());
  }
  if (names.size() == 1) return names;
  std::vector<std::string> sorted = names;
  std::sort(sorted.begin(), sorted.end());  // the ChannelList's own order, by name
  if (sorted == std::vector<std::string>{"B", "G", "R"}) return {"R", "G", "B"};
  if (sorted == std::vector<std::string>{"A", "B", "G", "R"}) return {"R", "G", "B", "A"};
  return {};
}

// A file's header, when the row takes the file.
struct Opened {
  std::unique_ptr<Imf::StdIFStream> stream;  // at the header's end
  Imath::Box2i window;                       // the data window
  Imath::Box2i display;                      // the display window: the image brume reads
  int width = 0, height = 0;                 // the display window's
  std::vector<std::string> names;  // in OpenImageIO's order
  int bits = 32;
  std::string description;
  bool blender = false;
  bool tiled = false;
  Imf::Compression compression = Imf::NO_COMPRESSION;
};

PixelWindow window_of(const Imath::Box2i& b) { return {b.min.x, b.min.y, b.max.x, b.max.y}; }

// The display window's size, refused when the data window reaches outside it.
void display_size(const std::string& path, const Imath::Box2i& data, const Imath::Box2i& display, int& w, int& h) {
  ExrPart p;
  p.data = window_of(data);
  p.display = window_of(display);
  const std::string why = exr_window_problem(p);
  if (!why.empty()) throw Error("cannot read '" + path + "': " + why);
  const long long ww = static_cast<long long>(display.max.x) - display.min.x + 1;
  const long long hh = static_cast<long long>(display.max.y) - display.min.y + 1;
  if (ww > INT_MAX || hh > INT_MAX)
    throw Error("cannot read '" + path + "': its display window declares " + std::to_string(ww) + " x " +
                std::to_string(hh) + " pixels");
  w = static_cast<int>(ww);
  h = static_cast<int>(hh);
}

[[noreturn]] void fail(const std::string& path, const std::exception& e) {
  throw Error("cannot read '" + path + "': " + e.what());
}

// False for a file the row does not take; brume::Error for a damaged one.
bool open_exr(const std::string& path, Opened& o) {
  check_exr_attributes(path);
  // The preamble: the magic number and the version field, whose flags say
  // multi-part and deep (non-image) before OpenEXR parses more.
  char b[8];
  {
    std::ifstream f(path, std::ios::binary);
    if (!f.read(b, 8) || !Imf::isImfMagic(b)) return false;
  }
  int version;
  std::memcpy(&version, b + 4, 4);  // little-endian, as the hosts brume builds for
  if (Imf::getVersion(version) != 2 || Imf::isMultiPart(version) || Imf::isNonImage(version) ||
      !Imf::supportsFlags(Imf::getFlags(version)))
    return false;
  Imf::Header h;
  try {
    o.stream = std::make_unique<Imf::StdIFStream>(path.c_str());
    o.stream->seekg(8);
    h.readFrom(*o.stream, version);
    h.sanityCheck(Imf::isTiled(version));
  } catch (const std::exception& e) {
    fail(path, e);
  }
  Imf::PixelType type = Imf::HALF;
  o.names = channel_order(h.channels(), type);
  if (o.names.empty()) return false;
  o.window = h.dataWindow();
  o.display = h.displayWindow();
  display_size(path, o.window, o.display, o.width, o.height);
  o.bits = type == Imf::HALF ? 16 : 32;
  if (const auto* c = h.findTypedAttribute<Imf::StringAttribute>("comments")) o.description = c->value();
  o.blender = h.findTypedAttribute<Imf::StringAttribute>("BlenderMultiChannel") != nullptr;
  o.tiled = Imf::isTiled(version);
  o.compression = h.compression();
  return true;
}

bool header(const std::string& path, Header& out) {
  Opened o;
  if (!open_exr(path, o)) return false;
  out.width = o.width;
  out.height = o.height;
  out.channels = static_cast<int>(o.names.size());
  return true;
}

// The pixels of a scanline file stored without compression, run-length or
// zip, through OpenEXR's C core (openexr.h): each chunk decompressed and
// unpacked straight into the image at its place, the chunks spread over the
// request's threads. InputFile gives the same values (tested:
// IO.ExrCoreRead*, against OpenImageIO, which reads through InputFile), but
// for these compressions its copyIntoFrameBuffer converts every value from
// the file's byte order one byte at a time. The demo's range map (1600 x
// 1120, one float channel, zip) on 2 threads: 49 ms of CPU through
// InputFile, 37 through the core; the demo's colour as a float RGB file 107
// against 72 (medians of 11, AMD EPYC family 26, 2026-12-06). Other files
// (tiled, piz, the lossy forms, four half channels) stay with InputFile.
// False when the file is not one this path takes; brume::Error for a damaged
// one.
struct CoreError {
  std::mutex m;
  std::string message;  // the first error the core reported
};
void core_error(exr_const_context_t ctxt, exr_result_t code, const char* msg) {
  void* user = nullptr;
  exr_get_user_data(ctxt, &user);
  if (!user) return;
  auto* e = static_cast<CoreError*>(user);
  try {  // nothing may unwind through the C library
    std::lock_guard<std::mutex> lock(e->m);
    if (e->message.empty()) e->message = msg ? msg : exr_get_default_error_message(code);
  } catch (...) {
  }
}

bool read_core(const std::string& path, const Opened& o, int threads, Image& img) {
  if (o.tiled) return false;
  // Four half channels: OpenEXR 3.1.5's core picks its own routine for
  // them (four interleaved 16-bit channels) and puts them in the wrong
  // places when asked for floats (the alpha's value in red; found by
  // IO.ExrRoundTrips* and IO.ExrCoreRead*). InputFile reads them.
  if (o.names.size() == 4 && o.bits == 16) return false;
  if (o.compression != Imf::NO_COMPRESSION && o.compression != Imf::RLE_COMPRESSION &&
      o.compression != Imf::ZIPS_COMPRESSION && o.compression != Imf::ZIP_COMPRESSION)
    return false;
  CoreError err;
  const auto fail_core = [&](exr_result_t code) {
    throw Error("cannot read '" + path + "': " +
                (err.message.empty() ? std::string(exr_get_default_error_message(code)) : err.message));
  };
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.error_handler_fn = core_error;
  init.user_data = &err;
  exr_context_t ctx = nullptr;
  if (const exr_result_t rv = exr_start_read(&ctx, path.c_str(), &init); rv != EXR_ERR_SUCCESS) {
    exr_finish(&ctx);
    fail_core(rv);
  }
  struct Finish {
    exr_context_t* c;
    ~Finish() { exr_finish(c); }
  } finish{&ctx};
  // The file as open_exr saw it: the same windows, storage and channels.
  exr_attr_box2i_t dw{}, disp{};
  exr_storage_t storage{};
  const exr_attr_chlist_t* list = nullptr;
  int32_t chunks = 0, lines = 0;
  if (exr_get_storage(ctx, 0, &storage) != EXR_ERR_SUCCESS || storage != EXR_STORAGE_SCANLINE ||
      exr_get_data_window(ctx, 0, &dw) != EXR_ERR_SUCCESS ||
      exr_get_display_window(ctx, 0, &disp) != EXR_ERR_SUCCESS || exr_get_channels(ctx, 0, &list) != EXR_ERR_SUCCESS ||
      exr_get_chunk_count(ctx, 0, &chunks) != EXR_ERR_SUCCESS ||
      exr_get_scanlines_per_chunk(ctx, 0, &lines) != EXR_ERR_SUCCESS || !list || lines < 1 ||
      dw.min.x != o.window.min.x || dw.min.y != o.window.min.y || dw.max.x != o.window.max.x ||
      dw.max.y != o.window.max.y || disp.min.x != o.display.min.x || disp.min.y != o.display.min.y ||
      disp.max.x != o.display.max.x || disp.max.y != o.display.max.y ||
      list->num_channels != static_cast<int>(o.names.size()))
    throw Error("cannot read '" + path + "': the file changed while it was read");
  const std::size_t C = o.names.size(), W = static_cast<std::size_t>(o.width);
  // The image's float at (x, y) of the file's coordinates, channel c.
  float* const data = img.data.data();
  const auto at = [&](int x, int y, std::size_t c) {
    return data + ((static_cast<std::size_t>(y - o.display.min.y) * W + static_cast<std::size_t>(x - o.display.min.x)) * C + c);
  };
  const auto slot = [&](const char* name) {
    for (std::size_t c = 0; c < C; ++c)
      if (o.names[c] == name) return static_cast<std::ptrdiff_t>(c);
    return std::ptrdiff_t{-1};
  };
  exr_result_t first = EXR_ERR_SUCCESS;
  bool changed = false;
  const int n = std::max(1, std::min(threads, 64));
#pragma omp parallel num_threads(n)
  {
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    bool made = false, routines = false;  // this thread's pipeline: initialised; its unpacking chosen
#pragma omp for schedule(dynamic, 1)
    for (int32_t k = 0; k < chunks; ++k) {
      exr_result_t rv;
      bool bad = false;
      exr_chunk_info_t info{};
      rv = exr_read_scanline_chunk_info(ctx, 0, dw.min.y + k * lines, &info);
      if (rv == EXR_ERR_SUCCESS) {
        rv = made ? exr_decoding_update(ctx, 0, &info, &dec) : exr_decoding_initialize(ctx, 0, &info, &dec);
        made = made || rv == EXR_ERR_SUCCESS;
      }
      if (rv == EXR_ERR_SUCCESS) {
        for (int16_t i = 0; i < dec.channel_count; ++i) {
          exr_coding_channel_info_t& ch = dec.channels[i];
          const std::ptrdiff_t c = slot(ch.channel_name);
          if (c < 0 || ch.x_samples != 1 || ch.y_samples != 1) {
            bad = true;
            break;
          }
          ch.decode_to_ptr = reinterpret_cast<uint8_t*>(at(dw.min.x, info.start_y, static_cast<std::size_t>(c)));
          ch.user_pixel_stride = static_cast<int32_t>(C * sizeof(float));
          ch.user_line_stride = static_cast<int32_t>(W * C * sizeof(float));
          ch.user_data_type = EXR_PIXEL_FLOAT;
          ch.user_bytes_per_element = sizeof(float);
        }
        if (!bad && !routines) {
          rv = exr_decoding_choose_default_routines(ctx, 0, &dec);
          routines = rv == EXR_ERR_SUCCESS;
        }
        if (!bad && routines) rv = exr_decoding_run(ctx, 0, &dec);
      }
      if (bad || rv != EXR_ERR_SUCCESS) {
#pragma omp critical(brume_exr_core)
        {
          if (bad) changed = true;
          else if (first == EXR_ERR_SUCCESS) first = rv;
        }
      }
    }
    exr_decoding_destroy(ctx, &dec);
  }
  if (changed) throw Error("cannot read '" + path + "': the file changed while it was read");
  if (first != EXR_ERR_SUCCESS) fail_core(first);
  return true;
}

// The other files (tiled, or another compression) through InputFile, its
// slices over the image.
void read_imf(const std::string& path, Opened& o, int threads, Image& img) {
  const int C = static_cast<int>(o.names.size());
  try {
    o.stream->seekg(0);
    Imf::InputFile in(*o.stream, ensure_pool(threads));
    if (in.header().dataWindow() != o.window || in.header().displayWindow() != o.display)
      throw Iex::InputExc("the file changed while it was read");
    // OpenEXR addresses a slice by (x, y) in the file's coordinates: the base
    // is where pixel (0, 0) would be, before the display window's origin
    // (the image is the display window; the data window's rows land inside).
    const std::size_t xs = static_cast<std::size_t>(C) * sizeof(float);
    const std::size_t ys = xs * static_cast<std::size_t>(o.width);
    char* base = reinterpret_cast<char*>(img.data.data()) -
                 static_cast<std::ptrdiff_t>(o.display.min.x) * static_cast<std::ptrdiff_t>(xs) -
                 static_cast<std::ptrdiff_t>(o.display.min.y) * static_cast<std::ptrdiff_t>(ys);
    Imf::FrameBuffer fb;
    for (int c = 0; c < C; ++c) {
      if (!in.header().channels().findChannel(o.names[static_cast<std::size_t>(c)]))
        throw Iex::InputExc("the file changed while it was read");
      fb.insert(o.names[static_cast<std::size_t>(c)],
                Imf::Slice(Imf::FLOAT, base + static_cast<std::size_t>(c) * sizeof(float), xs, ys));
    }
    in.setFrameBuffer(fb);
    in.readPixels(o.window.min.y, o.window.max.y);
  } catch (const std::exception& e) {
    fail(path, e);
  }
}

bool read(const ReadRequest& request, Decoded& out) {
  const std::string& path = request.path;
  Opened o;
  if (!open_exr(path, o)) return false;
  const int C = static_cast<int>(o.names.size());
  // One channel with alpha kept: OpenImageIO's call (a lone "A" is alpha).
  if (request.with_alpha && C == 1) return false;
  if (request.check) request.check(o.width, o.height, C);
  Image img(o.width, o.height, C);
  const bool padded = o.window != o.display;
  if (padded) std::fill(img.data.begin(), img.data.end(), request.pad);
  if (!read_core(path, o, request.threads, img)) read_imf(path, o, request.threads, img);
  out.img = std::move(img);
  out.info.format = "openexr";
  out.info.integer = false;
  out.info.bits = o.bits;
  out.info.channel_names = std::move(o.names);
  out.info.description = std::move(o.description);
  out.info.blender = o.blender;
  out.info.data_window = window_of(o.window);
  out.info.display_window = window_of(o.display);
  out.info.padded = padded;
  out.alpha = C == 4 ? 3 : -1;
  out.unassociated = false;  // OpenEXR's colour is premultiplied by alpha, by definition
  return true;
}

// The file a write goes to: stdio under OpenEXR's stream interface, keeping
// the first failure (and its errno) so that close() reports a write that
// OpenEXR's destructor could not finish (it swallows its exceptions).
class FileStream : public Imf::OStream {
 public:
  explicit FileStream(const std::string& path) : Imf::OStream(path.c_str()), f_(std::fopen(path.c_str(), "wb")) {
    if (!f_) Iex::throwErrnoExc("cannot open " + path + " for writing: %T.");
  }
  ~FileStream() override {
    if (f_) std::fclose(f_);
  }
  void write(const char c[], int n) override {
    if (std::fwrite(c, 1, static_cast<std::size_t>(n), f_) != static_cast<std::size_t>(n)) failed();
  }
  // Never throws: OutputFile's destructor calls it outside its try; a
  // failure is kept for close().
  std::uint64_t tellp() override {
    const off_t at = ftello(f_);
    if (at >= 0) return static_cast<std::uint64_t>(at);
    if (err_ == 0) err_ = errno != 0 ? errno : EIO;
    return 0;
  }
  void seekp(std::uint64_t pos) override {
    if (fseeko(f_, static_cast<off_t>(pos), SEEK_SET) != 0) failed();
  }
  int error() const { return err_; }  // the first failure's errno, 0 if none
  // Flushes and closes; false with errno set on this or an earlier failure.
  bool close() {
    const int r = std::fclose(f_);
    f_ = nullptr;
    if (err_ != 0) {
      errno = err_;
      return false;
    }
    return r == 0;
  }

 private:
  void failed() {
    if (err_ == 0) err_ = errno != 0 ? errno : EIO;
    Iex::throwErrnoExc("cannot write " + std::string(fileName()) + ": %T.", err_);
  }
  std::FILE* f_;
  int err_ = 0;
};

// Compressions by brume's names (format.hpp's rules: compression_rules).
Imf::Compression compression_of(const std::string& name) {
  static const std::pair<const char*, Imf::Compression> names[] = {
      {"auto", Imf::ZIP_COMPRESSION},    {"none", Imf::NO_COMPRESSION},   {"rle", Imf::RLE_COMPRESSION},
      {"zip", Imf::ZIP_COMPRESSION},     {"zips", Imf::ZIPS_COMPRESSION}, {"piz", Imf::PIZ_COMPRESSION},
      {"pxr24", Imf::PXR24_COMPRESSION}, {"b44", Imf::B44_COMPRESSION},   {"b44a", Imf::B44A_COMPRESSION},
      {"dwaa", Imf::DWAA_COMPRESSION},   {"dwab", Imf::DWAB_COMPRESSION}};
  for (const auto& [n, c] : names)
    if (name == n) return c;
  throw Iex::ArgExc("'" + name + "' is not an OpenEXR compression");
}

// The names OpenImageIO gives n channels (ImageSpec::default_channel_names,
// with Y for one, as brume always asked of it).
std::vector<std::string> channel_names(int n) {
  if (n == 1) return {"Y"};
  static const char* rgba[] = {"R", "G", "B", "A"};
  std::vector<std::string> names;
  for (int c = 0; c < n; ++c) names.emplace_back(c < 4 ? rgba[c] : "channel" + std::to_string(c));
  return names;
}

bool write(const std::string& tmp, const WriteRequest& r, std::string* why) {
  std::unique_ptr<FileStream> file;
  std::unique_ptr<Imf::OutputFile> out;
  try {
    // Header(w, h): windows from (0, 0), pixel aspect ratio 1, increasing y.
    Imf::Header h(r.width, r.height);
    const std::string& comp = r.compression.name;
    h.compression() = compression_of(comp);
    if (r.compression.level >= 0 && (comp == "zip" || comp == "zips")) h.zipCompressionLevel() = r.compression.level;
    if (comp == "dwaa" || comp == "dwab") {
      // OpenEXR's and OpenImageIO's default 45; the attribute names it for readers.
      if (r.compression.level >= 0) h.dwaCompressionLevel() = static_cast<float>(r.compression.level);
      h.insert("dwaCompressionLevel", Imf::FloatAttribute(h.dwaCompressionLevel()));
    }
    const Imf::PixelType type = r.type == Storage::f16 ? Imf::HALF : Imf::FLOAT;
    // Named channels (an output of layers: io.hpp's WriteOptions), each of
    // its own type, or OpenImageIO's names, all of the request's type.
    const std::vector<std::string> names =
        r.channel_names && !r.channel_names->empty() ? *r.channel_names : channel_names(r.channels);
    std::vector<Imf::PixelType> types(names.size(), type);
    if (r.channel_bits && r.channel_bits->size() == names.size())
      for (std::size_t c = 0; c < names.size(); ++c) types[c] = (*r.channel_bits)[c] == 16 ? Imf::HALF : Imf::FLOAT;
    for (std::size_t c = 0; c < names.size(); ++c) h.channels().insert(names[c], Imf::Channel(types[c]));
    if (!r.description.empty()) h.insert("comments", Imf::StringAttribute(r.description));
    if (r.srgb) h.insert("oiio:ColorSpace", Imf::StringAttribute("sRGB"));
    if (r.attributes)
      for (const auto& [k, v] : *r.attributes) h.insert(k, Imf::StringAttribute(v));
    const int threads = ensure_pool(r.threads);
    file = std::make_unique<FileStream>(tmp);
    out = std::make_unique<Imf::OutputFile>(*file, h, threads);
    // OpenEXR's writer takes slices of the file's own pixel type: a half
    // file's values are converted first, by Imath (round to nearest even, as
    // OpenImageIO converts), on the row's threads.
    const std::size_t C = static_cast<std::size_t>(r.channels);
    const std::size_t n = C * static_cast<std::size_t>(r.width) * static_cast<std::size_t>(r.height);
    std::vector<Imath::half> halves;
    const bool any_half = std::find(types.begin(), types.end(), Imf::HALF) != types.end();
    if (any_half) {
      halves.resize(n);
      const std::ptrdiff_t rows = r.height, row = static_cast<std::ptrdiff_t>(C) * r.width;
#pragma omp parallel for num_threads(std::max(1, std::min(r.threads, 64))) schedule(dynamic, kRowChunk)
      for (std::ptrdiff_t y = 0; y < rows; ++y)
        for (std::ptrdiff_t i = y * row; i < (y + 1) * row; ++i)
          if (types[static_cast<std::size_t>(i) % C] == Imf::HALF) halves[static_cast<std::size_t>(i)] = Imath::half(r.values[i]);
    }
    Imf::FrameBuffer fb;
    for (std::size_t c = 0; c < C; ++c) {  // (Slice takes char*; the writer only reads)
      const bool half = types[c] == Imf::HALF;
      const std::size_t value_bytes = half ? sizeof(Imath::half) : sizeof(float);
      const char* base = half ? reinterpret_cast<const char*>(halves.data()) : reinterpret_cast<const char*>(r.values);
      const std::size_t xs = C * value_bytes, ys = xs * static_cast<std::size_t>(r.width);
      fb.insert(names[c], Imf::Slice(types[c], const_cast<char*>(base) + c * value_bytes, xs, ys));
    }
    out->setFrameBuffer(fb);
    out->writePixels(r.height);
    out.reset();  // writes the line offset table
    if (!file->close()) {
      const int err = errno;
      if (why) *why = std::strerror(err);
      errno = err;
      return false;
    }
  } catch (const std::exception& e) {
    const int err = file && file->error() != 0 ? file->error() : errno;
    out.reset();
    file.reset();
    if (why) *why = e.what();
    errno = err;
    return false;
  }
  return true;
}

}  // namespace
}  // namespace exr_row

const Format& exr_format() {
  using namespace exr_row;
  static const Format f{.name = "openexr", .title = "OpenEXR", .extensions = {".exr"}, .bits = {"half", "float"},
                        .color_bits = "float", .data_bits = "float",
                        .compressions = {{"none", 1, 0, false}, {"rle", 1, 0, false}, {"zip", 1, 9, false},
                                         {"zips", 1, 9, false}, {"piz", 1, 0, false}, {"pxr24", 1, 0, true},
                                         {"b44", 1, 0, true}, {"b44a", 1, 0, true}, {"dwaa", 1, 1000, true},
                                         {"dwab", 1, 1000, true}},
                        .holds_data = true, .sniff = sniff, .header = header, .read = read, .write = write,
                        .auto_is = "zip"};
  return f;
}


std::string exr_window_problem(const ExrPart& p) {
  const PixelWindow& d = p.data;
  const PixelWindow& w = p.display;
  if (d.x0 >= w.x0 && d.y0 >= w.y0 && d.x1 <= w.x1 && d.y1 <= w.y1) return "";
  auto box = [](const PixelWindow& b) {
    return "(" + std::to_string(b.x0) + ", " + std::to_string(b.y0) + ")-(" + std::to_string(b.x1) + ", " +
           std::to_string(b.y1) + ")";
  };
  return "its data window " + box(d) + " reaches outside its display window " + box(w) +
         " (overscan); brume reads the display window, the frame the camera's intrinsics describe, and would "
         "drop the pixels outside it: crop the file to its display window first (oiiotool IN --cut " +
         std::to_string(w.width()) + "x" + std::to_string(w.height()) + "+" + std::to_string(w.x0) + "+" +
         std::to_string(w.y0) + " -o OUT)";
}

namespace {
// The preamble's version field, or false for a file without OpenEXR's magic.
bool exr_version(const std::string& path, int& version) {
  char b[8];
  std::ifstream f(path, std::ios::binary);
  if (!f.read(b, 8) || !Imf::isImfMagic(b)) return false;
  std::memcpy(&version, b + 4, 4);  // little-endian, as the hosts brume builds for
  return true;
}
}  // namespace

bool exr_layout(const std::string& path, ExrLayout& out) {
  int version = 0;
  if (!exr_version(path, version)) return false;
  check_exr_attributes(path);
  out = {};
  out.multipart = Imf::isMultiPart(version);
  try {
    Imf::MultiPartInputFile in(path.c_str(), 0);
    for (int i = 0; i < in.parts(); ++i) {
      const Imf::Header& h = in.header(i);
      ExrPart p;
      if (h.hasName()) p.name = h.name();
      for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
        p.channels.emplace_back(it.name());
        p.bits.push_back(it.channel().type == Imf::HALF ? 16 : 32);
      }
      p.data = {h.dataWindow().min.x, h.dataWindow().min.y, h.dataWindow().max.x, h.dataWindow().max.y};
      p.display = {h.displayWindow().min.x, h.displayWindow().min.y, h.displayWindow().max.x,
                   h.displayWindow().max.y};
      p.deep = h.hasType() && Imf::isDeepData(h.type());
      if (i == 0) out.blender = h.findTypedAttribute<Imf::StringAttribute>("BlenderMultiChannel") != nullptr;
      out.parts.push_back(std::move(p));
    }
  } catch (const std::exception& e) {
    throw Error("cannot read '" + path + "': " + e.what());
  }
  return true;
}

void exr_read_channels(const ReadRequest& request, int part, const std::vector<std::string>& names, float pad,
                       Decoded& out) {
  const std::string& path = request.path;
  ExrLayout layout;
  if (!exr_layout(path, layout)) throw Error("cannot read '" + path + "': not an OpenEXR file");
  if (part < 0 || part >= static_cast<int>(layout.parts.size()))
    throw Error("internal: part " + std::to_string(part) + " of '" + path + "'");
  const ExrPart& p = layout.parts[static_cast<std::size_t>(part)];
  if (p.deep)
    throw Error("cannot read '" + path + "'" + (p.name.empty() ? "" : " part '" + p.name + "'") +
                ": it is a deep image (many samples per pixel); brume reads flat images: flatten it first "
                "(oiiotool IN --flatten -o OUT)");
  const std::string why = exr_window_problem(p);
  if (!why.empty()) throw Error("cannot read '" + path + "': " + why);
  const int W = p.display.width(), H = p.display.height(), C = static_cast<int>(names.size());
  if (request.check) request.check(W, H, C);
  Image img(W, H, C);
  const bool padded = p.data != p.display;
  if (padded) std::fill(img.data.begin(), img.data.end(), pad);
  int bits = 16;
  std::string description;
  try {
    Imf::MultiPartInputFile file(path.c_str(), exr_row::ensure_pool(request.threads));
    Imf::InputPart in(file, part);
    const Imf::Header& h = in.header();
    if (const auto* c = h.findTypedAttribute<Imf::StringAttribute>("comments")) description = c->value();
    const std::size_t xs = static_cast<std::size_t>(C) * sizeof(float);
    const std::size_t ys = xs * static_cast<std::size_t>(W);
    char* base = reinterpret_cast<char*>(img.data.data()) -
                 static_cast<std::ptrdiff_t>(p.display.x0) * static_cast<std::ptrdiff_t>(xs) -
                 static_cast<std::ptrdiff_t>(p.display.y0) * static_cast<std::ptrdiff_t>(ys);
    Imf::FrameBuffer fb;
    for (int c = 0; c < C; ++c) {
      const std::string& n = names[static_cast<std::size_t>(c)];
      const Imf::Channel* ch = h.channels().findChannel(n);
      if (!ch) throw Iex::InputExc("it has no channel '" + n + "'");
      if (ch->xSampling != 1 || ch->ySampling != 1)
        throw Iex::InputExc("channel '" + n + "' is subsampled (" + std::to_string(ch->xSampling) + " x " +
                            std::to_string(ch->ySampling) + "); brume reads full-resolution channels");
      if (ch->type != Imf::HALF) bits = 32;
      fb.insert(n, Imf::Slice(Imf::FLOAT, base + static_cast<std::size_t>(c) * sizeof(float), xs, ys));
    }
    in.setFrameBuffer(fb);
    in.readPixels(p.data.y0, p.data.y1);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error("cannot read '" + path + "': " + e.what());
  }
  out.img = std::move(img);
  out.info.format = "openexr";
  out.info.integer = false;
  out.info.bits = bits;
  out.info.channel_names = p.channels;
  out.info.part = layout.multipart ? p.name : "";
  out.info.blender = layout.blender;
  out.info.data_window = p.data;
  out.info.display_window = p.display;
  out.info.padded = padded;
  out.info.channels_read = names;
  out.info.description = std::move(description);
  out.alpha = -1;
  out.unassociated = false;
}

}  // namespace brume::io
