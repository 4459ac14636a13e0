// brume — `brume batch --dataset DIR --layout L`: a manifest from a dataset's
// folder layout, with each dataset's depth convention written out as the
// depth flags (never guessed at run time).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <set>
#include <map>

#include "brume/batch.hpp"
#include "brume/error.hpp"
#include "brume/io.hpp"
#include "core/text.hpp"

namespace fs = std::filesystem;

namespace brume {

namespace {

std::string rel(const fs::path& p, const std::string& manifest_dir) {
  const fs::path base = fs::absolute(manifest_dir.empty() ? "." : manifest_dir).lexically_normal();
  return fs::absolute(p).lexically_normal().lexically_relative(base).generic_string();
}

std::string key_of(const fs::path& p, const fs::path& dir) {
  return fs::absolute(p).lexically_normal().lexically_relative(fs::absolute(dir).lexically_normal()).generic_string();
}

std::vector<fs::path> subdirs(const fs::path& dir) {
  std::vector<fs::path> v;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_directory()) v.push_back(e.path());
  std::sort(v.begin(), v.end());
  return v;
}

// A glob of one pattern relative to `dir`: '*' and '?' within one path
// component; returns (relative path, what the '*'s matched joined by '/').
std::vector<std::pair<std::string, std::string>> glob(const fs::path& dir, const std::string& pattern) {
  std::string re;
  for (char c : pattern) {
    if (c == '*') re += "([^/]*)";
    else if (c == '?') re += "([^/])";
    else if (std::string_view(".^$|()[]{}+\\").find(c) != std::string_view::npos) re += std::string("\\") + c;
    else re += c;
  }
  const std::regex rx(re);
  std::vector<std::pair<std::string, std::string>> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string r = key_of(e.path(), dir);
    std::smatch m;
    if (!std::regex_match(r, m, rx)) continue;
    std::string cap;
    for (std::size_t i = 1; i < m.size(); ++i) cap += (i > 1 ? "/" : "") + m[i].str();
    out.emplace_back(r, cap);
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

std::vector<nlohmann::json> dataset_manifest(const DatasetOptions& o) {
  const fs::path dir(o.dir);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error("--dataset '" + o.dir + "' is not a folder");
  std::vector<nlohmann::json> rows;
  const std::string& L = o.layout;
  if (o.lidar && L != "kitti")
    throw Error("--lidar with --dataset: only --layout kitti has LiDAR scans (velodyne/N.bin); drop --lidar");
  if (L == "middlebury") {
    // Middlebury 2005/2006 third size (the folders of ../shared/data): the
    // intensity I of disp1.png is the full-size disparity less dmin, so at
    // third size d = (I + dmin)/3 px at f = 3740/3 px, B = 160 mm (SOURCES.md);
    // I = 0 is unknown.
    for (const fs::path& s : subdirs(dir)) {
      if (!fs::exists(s / "view1.png") || !fs::exists(s / "disp1.png") || !fs::exists(s / "dmin.txt")) continue;
      double dmin = 0;
      std::istringstream f(read_input_file((s / "dmin.txt").string(), "--dataset", {4096, "dmin.txt holds one number"}));
      if (!(f >> dmin)) throw Error("--dataset: '" + (s / "dmin.txt").string() + "' holds no number (dmin)");
      rows.push_back({{"key", key_of(s / "view1.png", dir)},
                      {"image", rel(s / "view1.png", o.manifest_dir)},
                      {"disparity", rel(s / "disp1.png", o.manifest_dir)},
                      {"fx", 3740.0 / 3.0},
                      {"baseline", 0.16},
                      {"disparity-scale", 1.0 / 3.0},
                      {"disparity-offset", dmin / 3.0}});
    }
  } else if (L == "eth3d") {
    // ETH3D two-view (and Middlebury 2014): Z = f B / (d + doffs) from calib.txt; inf is unknown.
    for (const fs::path& s : subdirs(dir)) {
      if (!fs::exists(s / "im0.png") || !fs::exists(s / "disp0.pfm") || !fs::exists(s / "calib.txt")) continue;
      rows.push_back({{"key", key_of(s / "im0.png", dir)},
                      {"image", rel(s / "im0.png", o.manifest_dir)},
                      {"disparity", rel(s / "disp0.pfm", o.manifest_dir)},
                      {"calib", rel(s / "calib.txt", o.manifest_dir)}});
    }
  } else if (L == "kitti") {
    // KITTI object/raw: image_2/N.png with its Velodyne scan velodyne/N.bin
    // and calib/N.txt (projected through P2 R0_rect Tr_velo_to_cam). A lidar
    // scan is sparse: the effects' --complete auto completes it first.
    const fs::path img = dir / "image_2";
    if (!fs::is_directory(img)) throw Error("--dataset '" + o.dir + "' --layout kitti: no image_2/ folder");
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(img))
      if (e.is_regular_file() && e.path().extension() == ".png") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const fs::path& p : files) {
      const std::string n = p.stem().string();
      const fs::path velo = dir / "velodyne" / (n + ".bin"), calib = dir / "calib" / (n + ".txt");
      if (!fs::exists(velo) || !fs::exists(calib)) continue;
      rows.push_back({{"key", key_of(p, dir)},
                      {"image", rel(p, o.manifest_dir)},
                      {"velodyne", rel(velo, o.manifest_dir)},
                      {"kitti-calib", rel(calib, o.manifest_dir)}});
      if (o.lidar) rows.back()["lidar"] = rel(velo, o.manifest_dir);
    }
  } else if (L == "cityscapes") {
    // Cityscapes: leftImg8bit/<split>/<city>/<name>_leftImg8bit.png with
    // disparity/.../<name>_disparity.png (16-bit; p > 0: d = (p - 1)/256 px,
    // p = 0 invalid) and camera/.../<name>_camera.json (intrinsic fx, fy, u0,
    // v0 in px; extrinsic baseline in m). So --disparity-scale 1/256
    // --disparity-offset -1/256: p = 0 is unknown as every integer 0 is, and
    // p = 1 (d = 0, infinitely far) is unknown as d <= 0 is.
    const fs::path img = dir / "leftImg8bit";
    if (!fs::is_directory(img)) throw Error("--dataset '" + o.dir + "' --layout cityscapes: no leftImg8bit/ folder");
    const std::string suffix = "_leftImg8bit.png";
    std::vector<fs::path> files;
    for (const auto& e : fs::recursive_directory_iterator(img)) {
      const std::string n = e.path().filename().string();
      if (e.is_regular_file() && n.size() > suffix.size() && n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0)
        files.push_back(e.path());
    }
    std::sort(files.begin(), files.end());
    for (const fs::path& p : files) {
      const fs::path sub = p.parent_path().lexically_relative(img);
      const std::string name = p.filename().string().substr(0, p.filename().string().size() - suffix.size());
      const fs::path disp = dir / "disparity" / sub / (name + "_disparity.png");
      const fs::path cam = dir / "camera" / sub / (name + "_camera.json");
      if (!fs::exists(disp) || !fs::exists(cam)) continue;
      nlohmann::json c;
      try {
        c = nlohmann::json::parse(
            read_input_file(cam.string(), "--dataset", {1u << 20, "a Cityscapes camera JSON is a few hundred bytes"}));
        rows.push_back({{"key", key_of(p, dir)},
                        {"image", rel(p, o.manifest_dir)},
                        {"disparity", rel(disp, o.manifest_dir)},
                        {"disparity-scale", 1.0 / 256.0},
                        {"disparity-offset", -1.0 / 256.0},
                        {"fx", c.at("intrinsic").at("fx").get<double>()},
                        {"fy", c.at("intrinsic").at("fy").get<double>()},
                        {"cx", c.at("intrinsic").at("u0").get<double>()},
                        {"cy", c.at("intrinsic").at("v0").get<double>()},
                        {"baseline", c.at("extrinsic").at("baseline").get<double>()}});
      } catch (const nlohmann::json::exception& e) {
        throw Error("--dataset: camera file '" + cam.string() +
                    "' is not a Cityscapes camera JSON (intrinsic.fx, fy, u0, v0; extrinsic.baseline): " + e.what());
      }
    }
  } else if (L == "pairs") {
    if (o.image_glob.empty() || o.depth_glob.empty())
      throw Error("--layout pairs needs --image-glob and --depth-glob (relative to --dataset, '*' within one folder "
                  "level), e.g. --image-glob 'rgb/*.png' --depth-glob 'depth/*.exr'");
    const std::set<std::string> kinds = {"range", "z", "disparity", "depth-buffer", "inverse-depth", "normalized-depth"};
    if (!kinds.count(o.depth_kind))
      throw Error("--depth-kind '" + o.depth_kind +
                  "' is not allowed; use range, z, disparity, depth-buffer, inverse-depth or normalized-depth");
    std::map<std::string, std::string> depth;
    for (const auto& [r, cap] : glob(dir, o.depth_glob)) {
      if (depth.count(cap))
        throw Error("--depth-glob '" + o.depth_glob + "' matches '" + depth[cap] + "' and '" + r +
                    "' for the same '*' ('" + cap + "'); make the pattern more specific");
      depth[cap] = r;
    }
    for (const auto& [r, cap] : glob(dir, o.image_glob)) {
      const auto it = depth.find(cap);
      if (it == depth.end()) {
        std::fprintf(stderr, "brume batch --dataset: '%s' has no depth file matching '%s'; left out\n", r.c_str(),
                     o.depth_glob.c_str());
        continue;
      }
      rows.push_back({{"key", r}, {"image", rel(dir / r, o.manifest_dir)}, {o.depth_kind, rel(dir / it->second, o.manifest_dir)}});
    }
  } else {
    throw Error("--layout '" + L + "' is not allowed; use middlebury, eth3d, kitti, cityscapes or pairs");
  }
  if (rows.empty()) throw Error("--dataset '" + o.dir + "' --layout " + L + ": no frames found");
  return rows;
}

void write_manifest(const std::string& path, const std::vector<nlohmann::json>& rows) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  // A file name that is not UTF-8 (Linux allows any bytes) cannot go into a
  // manifest or, later, a record: refuse it by name rather than replace it.
  for (const auto& r : rows)
    for (const auto& [k, v] : r.items())
      if (v.is_string()) check_utf8(v.get_ref<const std::string&>(), "--dataset: the '" + k + "' file");
  std::string text;
  if (ext == ".jsonl" || ext == ".ndjson" || ext == ".json") {
    for (const auto& r : rows) text += r.dump() + "\n";
  } else if (ext == ".csv") {
    // Columns in first-seen order; numbers written to round trip (17 digits).
    std::vector<std::string> cols;
    for (const auto& r : rows)
      for (const auto& [k, v] : r.items())
        if (std::find(cols.begin(), cols.end(), k) == cols.end()) cols.push_back(k);
    // json's items() iterate in sorted order; put key and image first.
    std::stable_partition(cols.begin(), cols.end(), [](const std::string& c) { return c == "key" || c == "image"; });
    auto quote = [](std::string s) {
      if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
      std::string q = "\"";
      for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
      return q + "\"";
    };
    for (std::size_t i = 0; i < cols.size(); ++i) text += (i ? "," : "") + quote(cols[i]);
    text += "\n";
    for (const auto& r : rows) {
      for (std::size_t i = 0; i < cols.size(); ++i) {
        std::string v;
        if (r.contains(cols[i])) {
          const auto& x = r[cols[i]];
          if (x.is_string()) {
            v = x.get<std::string>();
          } else if (x.is_number_float()) {
            v = text::g(x.get<double>(), 17);
          } else {
            v = x.dump();
          }
        }
        text += (i ? "," : "") + quote(v);
      }
      text += "\n";
    }
  } else {
    throw Error("--manifest '" + path + "': a dataset's manifest is written as .csv or .jsonl");
  }
  OutputSet outs;
  outs.write_text(path, text, "--manifest");
  outs.commit();
}

}  // namespace brume
