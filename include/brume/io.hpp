// brume — image and range-map files.
//
// Formats: PNG (8/16-bit), JPEG, TIFF (integer and float), OpenEXR (any
// channel by name), PFM (Middlebury's: rows stored bottom to top, the sign of
// the scale gives the byte order, 1 or 3 channels) and Radiance HDR, each a
// row of the table of formats (src/io/formats/format.hpp) over its library
// (libspng, libjpeg-turbo, libtiff, OpenEXR; PFM and HDR brume's own). What
// no row takes goes through OpenImageIO, which libbrume loads on first use
// from its module brume_codec.so (looked for beside the executable or Python
// extension, in ../lib/brume/, at the configured install and build paths, or
// only at $BRUME_CODEC_MODULE when that is set; src/io/codec.hpp).
//
// Colour convention: integer files (8/16-bit) are sRGB-encoded and float files
// (EXR, PFM, float TIFF, HDR) are linear, unless a Transfer says otherwise.
// Every effect works in linear light.
//
// Outputs are written to a temporary file beside the target and renamed into
// place, so a failure never leaves a half-written file; OutputSet renames all
// of a run's outputs only after every one of them has been written.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "brume/image.hpp"
#include "brume/params.hpp"

namespace brume {

// gamma and table carry a parameter (TransferFunction); transfer_names()
// holds the words only, which --out-transfer takes.
enum class Transfer { automatic, srgb, linear, gamma, table };
const EnumNames<Transfer>& transfer_names();  // auto | srgb | linear
Transfer parse_transfer(const std::string& s, const std::string& flag);  // throws brume::Error
std::string to_string(Transfer t);

// How an input image's stored values v become linear light, as
// --image-transfer names it: a word of transfer_names(), or
//   gamma:G     linear = v^G (0 < G <= 10; a negative float value keeps its
//               sign: -(-v)^G), e.g. gamma:2.2 for a photo saved with a plain
//               1/2.2 power; gamma:1 is linear (and is recorded so);
//   table:FILE  a camera's measured response: FILE holds N >= 2 linear values
//               (text: numbers separated by spaces, commas or new lines, '#'
//               comments), non-decreasing, at v = i / (N - 1); linear
//               between them (N = 256 maps each 8-bit code to its entry
//               exactly). Float values outside [0, 1] are refused (a table
//               says nothing there).
// v is an integer file's count over 2^bits - 1, a float file's value. The
// curve applies to the colour channels, never to alpha.
struct TransferFunction {
  Transfer kind = Transfer::automatic;
  double gamma = 1.0;
  std::vector<double> table;  // table: the linear values at v = i / (N - 1)
  std::string table_path;     // table: FILE as given
  std::string table_sha256;   // table: FILE's SHA-256 when it was read
  TransferFunction() = default;
  TransferFunction(Transfer k) : kind(k) {}  // NOLINT(google-explicit-constructor): a word is a transfer
  bool operator==(Transfer k) const { return kind == k; }
  bool operator!=(Transfer k) const { return kind != k; }
  // linear light of v (gamma and table; the words are applied by the reader)
  double apply(double v) const;
};
// Parses a word, gamma:G or table:FILE (reading FILE); throws brume::Error
// naming `flag`, the value, what is allowed and the fix.
TransferFunction parse_transfer_function(const std::string& text, const std::string& flag);
// The text --image-transfer takes: "auto", "srgb", "linear", "gamma:2.2", "table:FILE".
std::string to_string(const TransferFunction& t);
// What --image-transfer's words and forms mean (every transfer parameter's help ends with it).
std::string transfer_help();
// Declares the TransferFunction member `m` as the text parameter `name` of
// `d` (the CLI's --NAME, a record's value, a Python keyword): its value is
// to_string's text, parsed (a table read) when the job is built. `of`: what
// it linearises ("the input").
template <class P>
ParamTable<P>& transfer_param(ParamTable<P>& d, const char* name, TransferFunction P::*m, const std::string& of) {
  ParamSpec s;
  s.name = name;
  s.kind = ParamKind::text;
  s.help = "transfer function of " + of + ": " + transfer_help();
  s.input_file = true;  // table:FILE: hashed with the image (file_record), checked by brume run
  s.input_file_prefix = "table:";
  return d.custom(
      std::move(s), [m](const P& p) { return nlohmann::json(to_string(p.*m)); },
      [m, flag = "--" + std::string(name)](P& p, const nlohmann::json& v) {
        p.*m = parse_transfer_function(v.get<std::string>(), flag);
      });
}

// A rectangle of pixels, corners included (OpenEXR's data and display
// windows: x0, y0 the top-left pixel, x1, y1 the bottom-right one).
struct PixelWindow {
  int x0 = 0, y0 = 0, x1 = -1, y1 = -1;
  int width() const { return x1 - x0 + 1; }
  int height() const { return y1 - y0 + 1; }
  bool operator==(const PixelWindow& o) const { return x0 == o.x0 && y0 == o.y0 && x1 == o.x1 && y1 == o.y1; }
  bool operator!=(const PixelWindow& o) const { return !(*this == o); }
};

struct FileInfo {
  std::string path;
  std::string format;  // OpenImageIO format name, e.g. "png", "openexr", "pnm"
  bool integer = false;  // stored as 8/16/32-bit integers
  int bits = 32;
  std::vector<std::string> channel_names;  // every channel of the file (of the part read, in a multi-part file)
  TransferFunction transfer = Transfer::linear;  // transfer function actually applied on read
  std::string description;  // the file's ImageDescription (brume embeds its JSON record there); empty if none
  // What was read ("files with layers" below): the layer (NAME of NAME.R, NAME.G,
  // NAME.B; a multi-part file's part; empty for the plain R, G, B or Y), the
  // channels the values came from in their order, and why those.
  std::string layer;
  std::string part;  // a multi-part OpenEXR file's part read (its name), else empty
  std::vector<std::string> channels_read;
  std::string channel_rule;
  bool blender = false;  // the file carries Blender's BlenderMultiChannel attribute (a multilayer render)
  // OpenEXR: the data window (the pixels the file holds) and the display
  // window (the image's frame, which brume reads: padded outside the data
  // window; zero-sized for other formats).
  PixelWindow data_window, display_window;
  bool padded = false;
};

// ---- files with layers (renders: docs/renderers.md) ----------------------------
// A file's channels are "plain" when they are R, G, B (A), or Y (A), or one
// channel of any name: a colour read takes R, G, B (Y three times), a scalar
// read the one channel (or R of an R, G, B whose channels are equal
// everywhere: grey saved as RGB) -- the rules of every file before layers.
// Any other set of channels (OpenEXR's layers, named NAME.CHANNEL: Blender's
// "ViewLayer.Combined.R", "ViewLayer.Depth.Z"; a multi-part file's parts) is
// read by name:
//  - colour: the layer NAME (NAME.R, NAME.G, NAME.B and NAME.A when present;
//    Nuke's NAME.red, ... too; for a multi-part file NAME may be a part's
//    name, whose R, G, B are read); unnamed, the one candidate layer (a set
//    of R, G, B under one prefix), refused when there are several, with the
//    list and the flag that names one;
//  - depth (ScalarRead::depth): the channel given, else the one channel named
//    like a depth pass (colour_layers / depth_passes below); Mist passes never.
// How a file of several channels is read when no layer or channel is named
// (--image-layer-rule, --depth-channel-rule): by name (the rules above), or
// the file's first channels in its order, as every read before record schema
// 4 (a record of schema <= 3 repeats with it: ParamTable::since).
enum class LayerRule { names, first };
struct ColorRead {
  TransferFunction transfer = Transfer::automatic;
  std::string layer;                         // NAME, or empty
  std::string layer_flag = "--image-layer";  // what names the layer, for messages (Python: "layer=")
  LayerRule rule = LayerRule::names;         // first: R, G, B are the file's first three channels (layer empty)
};
// Colour image -> linear float RGB (grey is expanded to RGB). `alpha`, when
// given, receives the alpha channel read with the colour (1 channel; empty
// when the file or layer has none): straight values for float files
// (OpenEXR's alpha, by which its colour is premultiplied), the count over
// 2^bits - 1 for integer files, never sRGB-decoded.
Image read_color(const std::string& path, const ColorRead& how, FileInfo* info = nullptr, Image* alpha = nullptr);
Image read_color(const std::string& path, Transfer transfer = Transfer::automatic,
                 FileInfo* info = nullptr);

// One channel of raw values (no transfer function): integer files give their
// counts (0..255 or 0..65535), float files their values. `channel` picks a
// channel by name ("Z", "R", "depth.Z"; in a multi-part file "PART.NAME" or a
// name only one part has); empty means the file must have one channel (or
// several identical ones, like a grey PNG saved as RGB), or, for depth,
// hold one channel named like a depth pass. Pixels of an OpenEXR display
// window outside its data window are NaN.
struct ScalarRead {
  std::string channel;
  std::string channel_flag = "--depth-channel";  // names the choice in messages
  bool depth = false;  // a depth source: a layered file's depth pass is looked for by name
  LayerRule rule = LayerRule::names;  // first (channel empty): the one channel, or the first of equal R, G, B
};
Image read_scalar(const std::string& path, const ScalarRead& how, FileInfo* info = nullptr);
Image read_scalar(const std::string& path, const std::string& channel = "",
                  FileInfo* info = nullptr);

// Whether a channel's name is a depth pass's: Z, depth (any case), *.depth,
// or *.Depth.Z (any case of "depth": Blender's "ViewLayer.Depth.Z", Nuke's
// "depth.Z"); and whether it is a Mist pass's (a component "Mist": 0-1
// mist, not metres, never taken as depth).
bool is_depth_pass_name(const std::string& channel);
bool is_mist_pass_name(const std::string& channel);
// The candidate colour layers among a part's channel names: each prefix
// (before the last '.'; "" for plain R, G, B) whose channels hold R, G, B
// (or red, green, blue), in the channels' order.
std::vector<std::string> colour_layers(const std::vector<std::string>& channels);
// Whether a set of channel names is plain (above).
bool plain_channels(const std::vector<std::string>& channels);

// An OpenEXR file's channels, with their storage bits (16 half, 32 float or
// uint): of its one part (a multi-part file gives multipart = true and no
// channels). Not OpenEXR: exr = false.
struct ExrChannels {
  bool exr = false, multipart = false, blender = false;
  std::vector<std::string> names;
  std::vector<int> bits;
};
ExrChannels exr_channels(const std::string& path);
// Those channels of a single-part OpenEXR file as float, in that order, on
// its display window (0 outside the data window).
Image read_exr_channels(const std::string& path, const std::vector<std::string>& names);

// The largest image or depth map a read accepts, in pixels (width × height).
// A header that declares more is refused before any allocation — a hostile or
// corrupt file must not exhaust memory. Process-wide, like OpenImageIO's own
// "limits:" attributes; `--max-pixels` on the command line sets it.
constexpr std::uint64_t default_max_pixels = 500'000'000;
std::uint64_t max_pixels();
void set_max_pixels(std::uint64_t n);  // n ≥ 1

// Every channel of an image as float with its alpha kept unassociated
// (straight, as stored), for the RGBA layers `brume insert` composites:
// integer files give each count over 2^bits - 1, alpha included
// (OpenImageIO's reading with oiio:UnassociatedAlpha; otherwise it would
// premultiply the sRGB-encoded values), float files their values. alpha:
// the alpha channel's index (-1: none); unassociated: the file says its
// alpha is straight (a float file's is premultiplied otherwise, EXR's
// definition). The table of formats' rows (src/io/formats/) read what they
// take -- 8/16-bit PNG with or without alpha, OpenEXR of R G B (A), ... --
// other files go through OpenImageIO. Errors name `what` (the flag) and the
// path.
struct ChannelImage {
  Image img;
  FileInfo info;  // transfer: linear (none applied)
  int alpha = -1;
  bool unassociated = false;
};
ChannelImage read_unassociated(const std::string& path, const std::string& what);

// The header of an image file (no pixels are read): size and channel count.
struct ImageHeader {
  int width = 0, height = 0, channels = 0;
  std::string format;
};
ImageHeader read_header(const std::string& path);

// The memory this process may still allocate, in bytes: the least of the
// kernel's MemAvailable, the cgroup's limit less its usage (v2 memory.max or v1
// memory.limit_in_bytes) and RLIMIT_AS less the current virtual size.
std::uint64_t memory_available();
// Refuse, before it starts, work that needs `bytes` more than memory_available();
// the error names `what`, both amounts and the fix.
void check_memory(std::uint64_t bytes, const std::string& what);
// What to say when std::bad_alloc reaches the top nonetheless (never
// "internal error"): the memory still available and the fixes.
std::string out_of_memory_message();

// ---- inputs: regular files within their limits, before anything is read ----
// Every file brume reads (images and depth maps, scans, calibrations, tables,
// records, manifests; the files a record's hashes name) is first opened with
// O_NONBLOCK -- a FIFO cannot hang the open -- and fstat'ed: it must be a
// regular file. A directory, a device (/dev/zero), a FIFO (/dev/stdin, a
// shell's <(...)) or a socket is refused by name, because every input is
// hashed into its run's record, which a stream cannot be. A file larger than
// its reader's limit is refused before it is read, naming its size, the
// limit and the limit's reason. A file that does not exist throws
// FileNotFound; every other refusal brume::Error. Messages name the file as
// input_name does: `what` (a flag, "--points"; may be empty) and the path.
struct InputLimit {
  std::uint64_t max_bytes = UINT64_MAX;
  std::string reason;  // why a larger file is not one of these ("a calibration is a few lines")
};
std::string input_name(const std::string& path, const std::string& what);
class InputFile {
 public:
  InputFile(const std::string& path, const std::string& what, const InputLimit& limit = {});
  ~InputFile();
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;
  std::uint64_t size() const { return size_; }  // bytes, as fstat gave them
  int fd() const { return fd_; }
  const std::string& name() const { return name_; }
  // Exactly `bytes` bytes from the current position, or an Error naming the file.
  void read_all(char* dst, std::uint64_t bytes);
  // The whole file (after check_memory for it), up to limit.max_bytes.
  std::string read_text(const InputLimit& limit);

 private:
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::string name_;
};
// The check alone (for readers that open the file themselves: the image
// codecs, hashing).
void check_input_file(const std::string& path, const std::string& what, const InputLimit& limit = {});
// A whole small input (a calibration, a table, a record, a manifest) as text.
std::string read_input_file(const std::string& path, const std::string& what, const InputLimit& limit);

// Signals and interrupted writes: SIGXFSZ (a file-size limit, `ulimit -f`) is
// ignored so that a too-large write fails with EFBIG and is reported, and
// SIGINT, SIGTERM and SIGHUP first remove the temporaries of outputs being
// written, then end the process as the signal would. Call once, from main().
void install_output_signal_handlers();

// Before any work: the directory an output `path` goes to exists and is
// writable, or a brume::Error naming `flag` and the path says how to fix it.
// Inside a CreateOutputFolders scope, a directory that does not exist yet
// passes when it can be created (its nearest existing ancestor is a
// writable directory).
void check_output_dir(const std::string& path, const std::string& flag);

// While one lives, on its thread, outputs may go to folders that do not
// exist yet: check_output_dir accepts them and OutputSet creates each
// folder when it writes a file there. A batch frame (brume batch, brume.dask)
// runs in one, so that a frame that fails before writing leaves no empty
// folder behind (folders made up front stayed when the frame failed, and
// removing them afterwards would race with the other workers' frames that
// share them).
class CreateOutputFolders {
 public:
  CreateOutputFolders();
  ~CreateOutputFolders();
  CreateOutputFolders(const CreateOutputFolders&) = delete;
  CreateOutputFolders& operator=(const CreateOutputFolders&) = delete;

 private:
  bool outer_;
};

// While one lives, on its thread, the codecs of image reads and writes use
// at most n threads (n > 0; 0: OpenMP's count, the default outside any
// scope): OpenEXR's pool when it decompresses or compresses, the segments
// of a PNG's deflate. The command line opens one with --threads around
// every job, and a batch frame with its worker's --threads, so that a
// setting that bounds the effect bounds the files' coding too. The bytes
// written do not depend on it.
class IoThreads {
 public:
  explicit IoThreads(int n);
  ~IoThreads();
  IoThreads(const IoThreads&) = delete;
  IoThreads& operator=(const IoThreads&) = delete;

 private:
  int outer_;
};

// sRGB transfer (IEC 61966-2-1), exact piecewise form.
float srgb_to_linear(float v);
float linear_to_srgb(float v);
// n values encoded to 8-bit sRGB codes exactly as writing the floats
// linear_to_srgb(max(v, 0)) to an 8-bit file would store them (by a table of
// the curve's 255 steps, built once; no pow per value).
void srgb_encode_8(const float* v, std::uint8_t* out, std::size_t n);

struct WriteOptions {
  std::string bits = "auto";   // auto | 8 | 16 | half | float
  Transfer transfer = Transfer::automatic;  // automatic: sRGB for integer outputs of colour
  bool is_color = true;        // false for data maps (transmission, scale): never sRGB-encoded
  // Non-empty for data whose values leave [0, 1] (metres, pixels): integer
  // storage and Radiance HDR are refused with this reason, never clipped.
  std::string float_reason;
  std::string description;     // embedded as ImageDescription where the format allows
  // The file's compression, NAME[:LEVEL] as OpenImageIO spells it: "auto" is
  // each format's default (compression_help()); which names a format takes:
  // compression_names().
  std::string compression = "auto";
  // OpenEXR only (an output of layers, for a compositor): each channel's
  // name ("ViewLayer.Combined.R") and storage bits (16 half, 32 float; empty:
  // all as `bits`), and string attributes to carry (Blender's
  // BlenderMultiChannel). Empty: R, G, B, A (Y for one channel).
  std::vector<std::string> channel_names;
  std::vector<int> channel_bits;
  std::vector<std::pair<std::string, std::string>> string_attributes;
};

// The --compression values a file of this extension takes (".png" -> "auto,
// none, zip, zip:0..9"), for help texts and messages.
std::string compression_names(const std::string& ext);
// The --compression help: every format's names and what auto writes.
std::string compression_help();

// Check, before any work is done, that `path` can be written with `opts`
// (known extension, existing writable directory, bit depth supported).
void check_writable(const std::string& path, const WriteOptions& opts, const std::string& flag);
// The part of check_writable that needs no directory: the extension is known
// and takes opts' bits and compression (brume batch checks every frame's
// outputs this way before the first frame runs).
void check_encoding(const std::string& path, const WriteOptions& opts, const std::string& flag);

class OutputSet {
 public:
  ~OutputSet();  // removes temporaries that were never committed
  // Encode and write `img` to a temporary file beside `path`.
  void write(const std::string& path, const Image& img, const WriteOptions& opts,
             const std::string& flag);
  // Write `text` (a parameter record, a CSV table) to a temporary file
  // beside `path`; it is renamed into place with the rest by commit().
  void write_text(const std::string& path, const std::string& text, const std::string& flag);
  // Rename every temporary into place.
  void commit();

 private:
  struct Pending {
    std::string tmp, final_path;
    int slot;          // in the signal handler's list of temporaries (-1: not listed)
    std::string flag;  // the option that named the output, for messages
  };
  void add_pending(const std::string& tmp, const std::string& final_path, const std::string& flag);
  std::vector<Pending> pending_;
  // Folders made for these outputs inside a CreateOutputFolders scope: the
  // destructor removes those no other set uses when they are empty (a run
  // that failed leaves no empty folder).
  std::vector<std::string> folders_;
};

// Convenience: write one file atomically.
void write_image(const std::string& path, const Image& img, const WriteOptions& opts,
                 const std::string& flag = "--out");

// Lower-case hex SHA-256 of a file's bytes (for parameter records).
std::string sha256_file(const std::string& path);

}  // namespace brume
