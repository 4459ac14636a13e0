// brume — an OpenEXR output a compositor keeps using (issue #50;
// brume/pipeline.hpp: OutputLayers; docs/renderers.md).
//
// A render goes back into a comp (Blender's compositor, Nuke) with its
// passes: so an OpenEXR output carries the colour under the layer's own
// names, its alpha as the medium composes it, and with --keep-layers every
// other channel of the input as stored, the medium as a layer of its own and
// the run's maps as layers. The colour an effect writes is already the
// premultiplied "over" of the medium on the image, C' = T C + (1 - T) B; the
// alpha that goes with it is A' = T A + (1 - T) (an opaque render stays 1).
// Blender's compositor shows each layer VIEW.PASS.CHANNEL as a socket of its
// Image node (one channel: a value socket, whatever its letter; checked with
// Blender 3.4 on tests/renders/), so the new layers are named like its passes.
#include <algorithm>
#include <cctype>
#include <filesystem>

#include "brume/error.hpp"
#include "brume/pipeline.hpp"

namespace brume {
namespace {

std::string join(const std::string& prefix, const std::string& c) { return prefix.empty() ? c : prefix + "." + c; }
std::string prefix_of(const std::string& n) {
  const auto d = n.rfind('.');
  return d == std::string::npos ? std::string() : n.substr(0, d);
}

// A map's layer: Transmission, BlurScale, ... (the flag in CamelCase otherwise).
std::string layer_name(const std::string& map) {
  if (map == "transmission") return "Transmission";
  if (map == "scale-map") return "BlurScale";
  if (map == "dof-scale-map") return "DofBlurScale";
  std::string out;
  bool up = true;
  for (char c : map) {
    if (c == '-') {
      up = true;
      continue;
    }
    out += up ? static_cast<char>(std::toupper(static_cast<unsigned char>(c))) : c;
    up = false;
  }
  return out;
}

// The letter of a one-channel layer (Blender shows any as a value socket).
constexpr const char* kValueChannel = "V";

// One channel of the output: its name, storage bits and values (a plane or
// every stride-th float of an interleaved image).
struct Channel {
  std::string name;
  int bits = 32;
  const float* data = nullptr;
  int stride = 1;
  std::vector<float> own;  // values computed here
};

}  // namespace

OutputLayers compose_output_layers(const OutputFiles& o, const LoadedInputs* in, const EffectOutput& out) {
  OutputLayers L;
  std::string ext = std::filesystem::path(o.out).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext != ".exr") return L;  // (--keep-layers with another format: refused by check_outputs)
  if (o.keep_layers && !in)
    throw Error("--keep-layers keeps the layers of an input image, and this command reads none; drop --keep-layers");
  const bool alpha_in = in && !in->alpha.empty() && o.alpha == OutAlpha::automatic;
  if (!alpha_in && !o.keep_layers) return L;  // R, G, B as ever

  const Image& main = out.main;
  const int W = main.width, H = main.height;
  const std::size_t n = main.pixels();
  if (main.channels != 3) throw Error("internal: an output of layers from a " + std::to_string(main.channels) + "-channel image");
  const Image* T = nullptr;
  if (!out.medium_map.empty()) {
    const auto it = out.maps.find(out.medium_map);
    if (it != out.maps.end() && !it->second.empty()) T = &it->second;
  }
  if (T && (T->width != W || T->height != H || T->channels != 1))
    throw Error("internal: the medium's transmission is not a 1-channel map of the output's size");
  const int new_bits = o.bits == "half" ? 16 : 32;
  nlohmann::json rec = nlohmann::json::object();
  Image kept_img;  // the input's other channels (--keep-layers), which `ch` points into

  // The colour layer under its own names (plain R, G, B; grey read as RGB).
  const FileInfo* info = in ? &in->image_info : nullptr;
  const std::string colour = info ? info->layer : std::string();
  std::vector<std::string> cn;
  if (info && info->channels_read.size() >= 3 && info->channels_read[0] != info->channels_read[1])
    cn.assign(info->channels_read.begin(), info->channels_read.begin() + 3);
  else
    cn = {join(colour, "R"), join(colour, "G"), join(colour, "B")};
  std::vector<Channel> ch;
  for (int c = 0; c < 3; ++c) ch.push_back({cn[static_cast<std::size_t>(c)], new_bits, main.data.data() + c, 3, {}});
  rec["colour"] = cn;

  // Its alpha: A' = T A + (1 - T), or A as read without a medium.
  if (alpha_in || o.keep_layers) {
    std::string an = join(colour, "A");
    if (info && info->channels_read.size() == 4 && alpha_in) an = info->channels_read[3];
    Channel a{an, new_bits, nullptr, 1, std::vector<float>(n)};
    for (std::size_t i = 0; i < n; ++i) {
      const float A = alpha_in ? in->alpha.data[i] : 1.0f;
      a.own[i] = T ? T->data[i] * A + (1.0f - T->data[i]) : A;
    }
    a.data = a.own.data();
    rec["alpha"] = {{"channel", an},
                    {"rule", !alpha_in ? (o.alpha == OutAlpha::off ? "--out-alpha off: 1 (the input's not read)"
                                                                   : "the input has no alpha: A = 1, A' = T + (1 - T) = 1")
                                       : T ? "A' = T A + (1 - T), premultiplied over (T: the " + out.medium_map + " map)"
                                           : "A as read (no medium composed; a blur of the colour leaves it as it is)"}};
    ch.push_back(std::move(a));
  }

  if (o.keep_layers) {
    const std::string view = prefix_of(colour);
    std::vector<std::string> made;
    if (T) {
      const std::string m = join(view, "Medium");
      static const char* rgba[] = {"R", "G", "B", "A"};
      for (int c = 0; c < 4; ++c) {
        Channel k{join(m, rgba[c]), new_bits, nullptr, 1, std::vector<float>(n)};
        for (std::size_t i = 0; i < n; ++i)
          k.own[i] = c < 3 ? (1.0f - T->data[i]) * out.medium_airlight[static_cast<std::size_t>(c)] : 1.0f - T->data[i];
        k.data = k.own.data();
        made.push_back(k.name);
        ch.push_back(std::move(k));
      }
      rec["medium"] = {{"layer", m}, {"rule", "(1 - T) B, alpha 1 - T"},
                       {"airlight", {out.medium_airlight[0], out.medium_airlight[1], out.medium_airlight[2]}}};
    }
    nlohmann::json maps = nlohmann::json::object();
    for (const auto& [name, img] : out.maps) {
      if (img.empty() || img.width != W || img.height != H) continue;
      const std::string l = join(view, layer_name(name));
      static const char* rgb[] = {"R", "G", "B"};
      std::vector<std::string> names;
      for (int c = 0; c < img.channels; ++c) {
        const std::string cname = img.channels == 1 ? kValueChannel : c < 3 ? rgb[c] : "C" + std::to_string(c);
        ch.push_back({join(l, cname), 32, img.data.data() + c, img.channels, {}});
        names.push_back(join(l, cname));
        made.push_back(join(l, cname));
      }
      maps[name] = names;
    }
    rec["maps"] = maps;
    // The input's other channels, as stored.
    nlohmann::json kept = nlohmann::json::array(), dropped = nlohmann::json::array();
    if (info && info->format == "openexr") {
      const ExrChannels ec = exr_channels(info->path);
      if (ec.multipart)
        throw Error("--keep-layers: '" + info->path + "' is a multi-part OpenEXR file; brume keeps the channels of a "
                    "single-part file (Blender's multilayer files are one part): merge its parts first (oiiotool IN "
                    "--siappendall -o OUT), or drop --keep-layers");
      std::vector<std::string> keep;
      std::vector<int> keep_bits;
      for (std::size_t c = 0; c < ec.names.size(); ++c) {
        const std::string& nm = ec.names[c];
        const bool read = std::find(info->channels_read.begin(), info->channels_read.end(), nm) !=
                              info->channels_read.end() ||
                          std::find(cn.begin(), cn.end(), nm) != cn.end() ||
                          (ch.size() > 3 && nm == ch[3].name);
        if (read) continue;
        if (std::find(made.begin(), made.end(), nm) != made.end()) {
          dropped.push_back(nm);  // this run's layer of the same name replaces it
          continue;
        }
        keep.push_back(nm);
        keep_bits.push_back(ec.bits[c]);
      }
      if (!keep.empty()) {
        kept_img = read_exr_channels(info->path, keep);
        if (kept_img.width != W || kept_img.height != H)
          throw Error("internal: --keep-layers read '" + info->path + "' at " + kept_img.size_string() +
                      ", the output is " + main.size_string());
        for (std::size_t c = 0; c < keep.size(); ++c) {
          ch.push_back({keep[c], keep_bits[c], kept_img.data.data() + c, static_cast<int>(keep.size()), {}});
          kept.push_back(keep[c]);
        }
      }
      if (ec.blender) L.attributes.emplace_back("BlenderMultiChannel", "Blender V2.55.1 and newer");
    }
    rec["kept"] = kept;
    if (!dropped.empty()) rec["replaced"] = dropped;
  }

  const int C = static_cast<int>(ch.size());
  L.image = Image(W, H, C);
  for (int c = 0; c < C; ++c) {
    const Channel& k = ch[static_cast<std::size_t>(c)];
    for (std::size_t i = 0; i < n; ++i) L.image.data[i * C + c] = k.data[i * static_cast<std::size_t>(k.stride)];
    L.names.push_back(k.name);
    L.bits.push_back(k.bits);
  }
  rec["channels"] = L.names;
  L.record = rec;
  return L;
}

}  // namespace brume
