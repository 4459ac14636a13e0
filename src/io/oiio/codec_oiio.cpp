// brume_codec.so: brume's calls into OpenImageIO, in a module of their own
// so that only the processes that need a codec pay for loading it
// (src/io/codec.hpp). Nothing here throws across the module boundary.
#include <OpenImageIO/imageio.h>

#include <exception>

#include "io/codec.hpp"

namespace {
using brume::codec::Api;
using brume::codec::InputSpec;

class OiioInput final : public brume::codec::Input {
 public:
  explicit OiioInput(std::unique_ptr<OIIO::ImageInput> in) : in_(std::move(in)) {
    const OIIO::ImageSpec& s = in_->spec();
    spec_.width = s.width;
    spec_.height = s.height;
    spec_.channels = s.nchannels;
    spec_.floating = s.format.is_floating_point();
    spec_.container_bits = static_cast<int>(s.format.size() * 8);
    spec_.bits_per_sample = s.get_int_attribute("oiio:BitsPerSample", 0);
    spec_.channel_names.assign(s.channelnames.begin(), s.channelnames.end());
    spec_.description = s.get_string_attribute("ImageDescription");
    spec_.format = in_->format_name();
    spec_.alpha_channel = s.alpha_channel;
    spec_.unassociated_alpha = s.get_int_attribute("oiio:UnassociatedAlpha", 0) != 0;
  }
  const InputSpec& spec() const override { return spec_; }
  bool read_float(float* out) override {
    try {
      return in_->read_image(0, 0, 0, spec_.channels, OIIO::TypeDesc::FLOAT, out);
    } catch (const std::exception& e) {
      extra_ = e.what();
      return false;
    }
  }
  std::string error() override {
    std::string e = in_->geterror();
    return e.empty() ? extra_ : e;
  }
  void close() override { in_->close(); }

 private:
  std::unique_ptr<OIIO::ImageInput> in_;
  InputSpec spec_;
  std::string extra_;
};

std::unique_ptr<brume::codec::Input> open_input(const std::string& path, bool unassociated_alpha, std::string* err) {
  try {
    std::unique_ptr<OIIO::ImageInput> in;
    if (unassociated_alpha) {
      // Keep PNG/TIFF alpha unassociated: OpenImageIO would otherwise
      // premultiply the sRGB-encoded values, which is not linear-light coverage.
      OIIO::ImageSpec config;
      config.attribute("oiio:UnassociatedAlpha", 1);
      in = OIIO::ImageInput::open(path, &config);
    } else {
      in = OIIO::ImageInput::open(path);
    }
    if (!in) {
      *err = OIIO::geterror();
      return nullptr;
    }
    return std::make_unique<OiioInput>(std::move(in));
  } catch (const std::exception& e) {
    *err = e.what();
    return nullptr;
  }
}

const Api kApi{brume::codec::kCodecTag, &open_input};
}  // namespace

extern "C" __attribute__((visibility("default"))) const Api* brume_codec_api() { return &kApi; }
