// brume study diffusion — Hansard §5.2-5.3 (Figs. 6-7) on brume's own code,
// with the peers a user would pick instead and a leakage experiment.
//
// accuracy.csv: scheme,precision,backend,sigma,rms,iterations,spread
//   RMS against a true double-precision Gaussian of sqrt(sigma^2 - sigma0^2)
//   (sampled kernel of radius 5 sigma, normalised, half-sample mirror) over
//   the image without a 4 sigma border, linear RGB in [0, 1]; "spread" is the
//   per-axis standard deviation an impulse reaches (target
//   sqrt(sigma^2 - sigma0^2)). Rows for brume's three schemes in f32 and f16
//   on each backend, and for the peers "gather" (direct Gaussian, radius
//   3 s) and "mipmap" (study/include/brume/peers.hpp).
// speed.csv: method,precision,backend,sigma,seconds,iterations,map,runs
//   on a 1600x1120 image (timings do not depend on content, except the
//   gather's on the map): map "constant" is sigma everywhere (the paper's
//   experiment; brume's uniform path), map "varying" is a haze-like map
//   sigma0 + R'^{3/2}(sigma - sigma0) from the demo scene's range. Peers:
//   OpenCV's GaussianBlur (space-invariant), the direct gather, the mip-map
//   and a memory-streaming floor (copying the RGBA float image as many
//   times as invariant-exact iterates). Median of 3 after a warm-up; a case
//   whose first run takes over 2 s is timed once (runs = 1). GPU times are
//   the diffusion passes alone (timer queries, else glFinish wall time).
// leakage.csv: method,edge_rate,backend,sigma_far,into_near_mean,
//   into_near_max,into_far_mean
//   A sharp near square (sigma = sigma0, green) on a far flat background
//   (sigma_far, red): the background colour found in the square's rim (the
//   pixels within 2 px of its edge: mean, and max over the whole square),
//   and the square's colour found in the background within sigma_far of it.
// summary.md: the key figures as Markdown tables (RMS at 5, 10, 25; time and
//   iterations at 25; ratios against each peer; leakage).
// leakage_crops/<method>_<edge rate>.png: the square's corner for each
//   method (8-bit sRGB). The figures (accuracy.png, speed.png, leakage.png)
//   are drawn from these files by matplotlib: python3 -m brume.plots DIR
//   (python/brume/plots.py), whose command the study prints.
//
// Images: the accuracy part uses a real 1600x1120 image in [0, 1], a 4x4
// mosaic of 400x280 crops of the photographs in ../shared/data (Middlebury
// 2005, KITTI, ETH3D; the paper used Middlebury "Pipes", which is not in the
// data), or --image. --quick uses Middlebury Art at 463x370 and a few sigma.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "brume/demo_scene.hpp"
#include "brume/diffusion.hpp"
#include "brume/error.hpp"
#include "brume/gpu.hpp"
#include "brume/io.hpp"
#include "brume/peers.hpp"
#include "brume_reference.hpp"
#include "brume_study/study.hpp"
#include "brume_opencv.hpp"

namespace fs = std::filesystem;
using namespace brume;
using Clock = std::chrono::steady_clock;

namespace {

// True Gaussian reference in double (separable, radius 5 sigma, mirror), RGB
// only: the tests' independent reference (study/reference).
Image gaussian(const Image& in, double sigma) { return reference::gaussian_reference(in, sigma, 3); }

double rms_rgb(const Image& a, const Image& b, int border) {
  double ss = 0;
  std::size_t n = 0;
  for (int y = border; y < a.height - border; ++y)
    for (int x = border; x < a.width - border; ++x)
      for (int c = 0; c < 3; ++c) {
        const double e = static_cast<double>(a.at(x, y, c)) - b.at(x, y, c);
        ss += e * e;
        ++n;
      }
  return n ? std::sqrt(ss / n) : NAN;
}

Image rgba(const Image& rgb) {
  Image f(rgb.width, rgb.height, 4, 1.0f);
  for (std::size_t i = 0; i < rgb.pixels(); ++i)
    for (int c = 0; c < 3; ++c) f.data[i * 4 + c] = rgb.data[i * rgb.channels + c];
  return f;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

std::string data_dir() {
  // BRUME_DATA_DIR when set and not empty (as the tests read it), else the
  // shared data beside the repository, found from the working directory.
  if (const char* env = std::getenv("BRUME_DATA_DIR"); env && *env) return env;
  for (fs::path p = fs::current_path(); !p.empty(); p = p.parent_path()) {
    if (fs::exists(p / "shared" / "data")) return (p / "shared" / "data").string();
    if (p == p.parent_path()) break;
  }
  return "";
}

// The 1600x1120 accuracy image: a 4x4 mosaic of 400x280 crops (x, y) of the
// real photographs in ../shared/data, linear RGB in [0, 1].
Image study_mosaic(const std::string& data) {
  struct Tile {
    const char* file;
    int x, y;
  };
  const Tile tiles[16] = {
      {"middlebury2005_thirdsize/Art/view1.png", 0, 0},      {"kitti_object_000001/image_2/000001.png", 0, 95},
      {"middlebury2005_thirdsize/Books/view1.png", 47, 90},  {"eth3d_two_view/playground_1l/im0.png", 0, 100},
      {"middlebury2005_thirdsize/Dolls/view1.png", 0, 45},   {"middlebury2005_thirdsize/Laundry/view1.png", 47, 0},
      {"kitti_object_000001/image_2/000001.png", 421, 95},   {"middlebury2005_thirdsize/Moebius/view1.png", 0, 90},
      {"eth3d_two_view/terrace/im0.png", 150, 80},           {"middlebury2005_thirdsize/Reindeer/view1.png", 30, 45},
      {"middlebury2005_thirdsize/Art/view1.png", 63, 90},    {"kitti_object_000001/image_2/000001.png", 842, 95},
      {"middlebury2005_thirdsize/Books/view1.png", 0, 0},    {"eth3d_two_view/playground_1l/im0.png", 541, 180},
      {"middlebury2005_thirdsize/Moebius/view1.png", 63, 0}, {"middlebury2005_thirdsize/Dolls/view1.png", 47, 90},
  };
  Image out(1600, 1120, 3);
  std::map<std::string, Image> cache;
  for (int t = 0; t < 16; ++t) {
    const std::string path = data + "/" + tiles[t].file;
    if (!cache.count(path)) {
      if (!fs::exists(path))
        throw Error("study image: " + path + " not found (the mosaic needs ../shared/data); give --image FILE");
      cache[path] = read_color(path);
    }
    const Image& src = cache[path];
    const int ox = (t % 4) * 400, oy = (t / 4) * 280;
    if (tiles[t].x + 400 > src.width || tiles[t].y + 280 > src.height)
      throw Error("study image: " + path + " is smaller than the crop it is used for");
    for (int y = 0; y < 280; ++y)
      for (int x = 0; x < 400; ++x)
        for (int c = 0; c < 3; ++c) out.at(ox + x, oy + y, c) = std::clamp(src.at(tiles[t].x + x, tiles[t].y + y, c), 0.0f, 1.0f);
  }
  return out;
}

struct StudyBackend {
  std::string name;
  GpuContext* gpu = nullptr;
  bool software = false;  // a software rasteriser (llvmpipe): skip the standard scheme's long runs
};

// Runs brume's diffusion; returns the plan and, for the GPU, the diffusion
// passes' time in seconds through *gpu_seconds.
DiffusionPlan run_brume(const StudyBackend& b, Image& f, const Image& map, double smax, const DiffusionParams& p,
                        double* gpu_seconds = nullptr) {
  if (!b.gpu) return diffuse(f, map, smax, p);
  GpuTiming t;
  const DiffusionPlan plan = diffuse_gpu(*b.gpu, f, map, smax, p, GpuFilter::automatic, &t);
  if (gpu_seconds) *gpu_seconds = t.diffuse_ms * 1e-3;
  return plan;
}

// Median of 3 timed runs after a warm-up, or one run when it takes > 2 s.
// `fn` returns its own time in seconds when it measures one (GPU), else < 0.
struct Timed {
  double seconds;
  int runs;
};
bool g_quick = false;  // --quick: one timed run after the warm-up
Timed time_it(const std::function<double()>& fn) {
  auto once = [&] {
    const auto t0 = Clock::now();
    const double own = fn();
    const double wall = std::chrono::duration<double>(Clock::now() - t0).count();
    return own >= 0 ? own : wall;
  };
  const double first = once();
  if (first > 2.0) return {first, 1};
  std::vector<double> t;
  for (int r = 0; r < (g_quick ? 1 : 3); ++r) t.push_back(once());
  return {median(t), static_cast<int>(t.size())};
}

// Impulse spread (per-axis standard deviation) of a constant-scale blur.
double impulse_spread(const std::function<void(Image&, const Image&)>& blur, double sigma) {
  const int n = 2 * static_cast<int>(std::ceil(6 * sigma)) + 3;  // no mass reaches the border
  Image imp(n, n, 4, 0.0f);
  imp.at(n / 2, n / 2, 0) = 1.0f;
  blur(imp, Image(n, n, 1, static_cast<float>(sigma)));
  double m = 0, v = 0;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) m += imp.at(x, y, 0), v += imp.at(x, y, 0) * (x - n / 2) * (x - n / 2);
  return std::sqrt(v / m);
}

std::string fmt(double v, const char* f = "%.3g") {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

// One CSV row as a record the summary and the plots read back.
struct AccRow {
  std::string scheme, precision, backend;
  double sigma, rms;
  int iterations;
  double spread;
};
struct SpeedRow {
  std::string method, precision, backend;
  double sigma, seconds;
  int iterations;
  std::string map;
};
struct LeakRow {
  std::string method, edge, backend;
  double into_near_mean, into_near_max, into_far_mean;
};

// A method's name in the summary's tables.
std::string label_of(const std::string& method, const std::string& prec, const std::string& backend) {
  std::string m = method.rfind("brume-", 0) == 0 ? method.substr(6) : method;
  if (m == "opencv-gaussianblur") return "OpenCV GaussianBlur";
  if (m == "memory-floor") return "memory floor (copy x N)";
  if (m == "mipmap") return "mip-map (peer)";
  if (m == "gather") return "direct gather (peer)";
  return m + " " + prec + (backend == "gpu" ? " GPU" : "");
}

// The leakage crops: the near square's top-left corner (2c x 2c pixels
// around (q0, q0)) of each method's result, unscaled, as 8-bit sRGB PNG in
// leakage_crops/<method>_<edge rate>.png (<method>.png for the peers), for
// the figure python/brume/plots.py draws beside the CSVs.
void write_crops(OutputSet& outs, const fs::path& dir, const std::vector<std::pair<std::string, Image>>& crops, int n,
                 int q0) {
  const fs::path cdir = dir / "leakage_crops";
  std::error_code ec;
  fs::create_directories(cdir, ec);
  if (!fs::is_directory(cdir)) throw Error("--out-dir: '" + cdir.string() + "' cannot be created");
  WriteOptions png;
  png.bits = "8";
  png.transfer = Transfer::srgb;  // the bytes a viewer shows; plots.py reads them as they are
  png.is_color = true;
  const int c = n / 8;
  for (const auto& [file, g] : crops) {
    Image crop(2 * c, 2 * c, 3);
    for (int y = 0; y < 2 * c; ++y)
      for (int x = 0; x < 2 * c; ++x)
        for (int ch = 0; ch < 3; ++ch) crop.at(x, y, ch) = std::clamp(g.at(q0 - c + x, q0 - c + y, ch), 0.0f, 1.0f);
    outs.write((cdir / (file + ".png")).string(), crop, png, "--out-dir");
  }
}

// The key figures as Markdown tables.
void write_summary(OutputSet& outs, const fs::path& dir, const std::vector<AccRow>& acc, const std::vector<SpeedRow>& spd,
                   const std::vector<LeakRow>& leak, const std::string& acc_name, const Image& acc_img, int W, int H,
                   double sfar) {
  std::ostringstream o;
  std::vector<double> key;
  for (double s : {5.0, 10.0, 25.0})
    if (std::any_of(acc.begin(), acc.end(), [&](const AccRow& r) { return r.sigma == s; })) key.push_back(s);
  double smax_acc = 0;
  for (const AccRow& r : acc) smax_acc = std::max(smax_acc, r.sigma);
  if (key.empty() || key.back() != smax_acc) key.push_back(smax_acc);
  o << "Accuracy on " << acc_name << " (" << acc_img.width << "x" << acc_img.height
    << "): RMS against a true Gaussian of sqrt(sigma^2 - 1).\n\n| method | precision | backend |";
  for (double s : key) o << " RMS at " << s << " px |";
  o << " iterations at " << smax_acc << " | impulse spread at " << smax_acc << " (target "
    << fmt(std::sqrt(smax_acc * smax_acc - 1), "%.2f") << ") |\n|---|---|---|";
  for (std::size_t i = 0; i < key.size() + 2; ++i) o << "---|";
  o << "\n";
  std::vector<std::tuple<std::string, std::string, std::string>> methods;
  for (const AccRow& r : acc)
    if (std::find(methods.begin(), methods.end(), std::make_tuple(r.scheme, r.precision, r.backend)) == methods.end())
      methods.emplace_back(r.scheme, r.precision, r.backend);
  for (const auto& [m, pr, b] : methods) {
    o << "| " << m << " | " << pr << " | " << b << " |";
    const AccRow* last = nullptr;
    for (double s : key) {
      const AccRow* hit = nullptr;
      for (const AccRow& r : acc)
        if (r.scheme == m && r.precision == pr && r.backend == b && r.sigma == s) hit = &r;
      o << " " << (hit ? fmt(hit->rms, "%.2e") : "-") << " |";
      if (s == smax_acc) last = hit;
    }
    o << " " << (last && last->iterations ? std::to_string(last->iterations) : "-") << " | "
      << (last ? fmt(last->spread, "%.2f") : "-") << " |\n";
  }

  double smax_spd = 0;
  for (const SpeedRow& r : spd) smax_spd = std::max(smax_spd, r.sigma);
  auto find = [&](const std::string& m, const std::string& map) -> const SpeedRow* {
    for (const SpeedRow& r : spd)
      if (r.method == m && r.map == map && r.sigma == smax_spd && r.backend == "cpu" && r.precision == "f32") return &r;
    return nullptr;
  };
  for (const char* map : {"constant", "varying"}) {
    const std::string mp = map;
    o << "\nSpeed at sigma = " << smax_spd << " px on " << W << "x" << H << ", "
      << (mp == "constant" ? "constant sigma (the paper's experiment)" : "space-variant haze map")
      << ": time, and brume's time as a ratio of each peer's (below 1: brume is faster).\n\n"
      << "| method | precision | backend | time [ms] | iterations |";
    std::vector<const SpeedRow*> peers;  // OpenCV and the floor exist for the constant map only
    for (const char* p : {"opencv-gaussianblur", "gather", "mipmap", "memory-floor"})
      if (const SpeedRow* r = find(p, mp)) peers.push_back(r);
    for (const SpeedRow* p : peers) o << " / " << label_of(p->method, "f32", "cpu") << " |";
    o << "\n|---|---|---|---|---|";
    for (std::size_t i = 0; i < peers.size(); ++i) o << "---|";
    o << "\n";
    for (const SpeedRow& r : spd) {
      if (r.sigma != smax_spd || r.map != mp) continue;
      o << "| " << r.method << " | " << r.precision << " | " << r.backend << " | " << fmt(r.seconds * 1e3, "%.1f") << " | "
        << (r.iterations ? std::to_string(r.iterations) : "-") << " |";
      for (const SpeedRow* p : peers) o << " " << (r.method.rfind("brume-", 0) == 0 ? fmt(r.seconds / p->seconds, "%.2f") : "") << " |";
      o << "\n";
    }
  }

  o << "\nLeakage across a depth edge: a sharp near square (sigma0, green) on a flat far background (sigma "
    << sfar << " px, red). Background colour in the square's 2 px rim (mean, and max over the square), and the "
       "square's colour in the background within "
    << sfar << " px of it.\n\n| method | edge rate | backend | background in near rim | max in near square | near colour in far ring |\n|---|---|---|---|---|---|\n";
  for (const LeakRow& r : leak)
    o << "| " << r.method << " | " << r.edge << " | " << r.backend << " | " << fmt(r.into_near_mean, "%.4f") << " | "
      << fmt(r.into_near_max, "%.4f") << " | " << fmt(r.into_far_mean, "%.4f") << " |\n";
  outs.write_text((dir / "summary.md").string(), o.str(), "--out-dir");
}

}  // namespace

int run_study(const std::string& what, const std::string& out_dir, bool quick, const std::string& backend,
              const std::string& image_path, const std::string& part) {
  if (what != "diffusion") throw Error("brume study '" + what + "': the only study is 'diffusion'");
  if (part != "all" && part != "leakage")
    throw Error("--only '" + part + "' is not a part of the study; use all or leakage");
  // --only leakage: the leakage experiment alone (leakage.csv, leakage.png),
  // e.g. after a change to the edge rates, without re-timing the speed part.
  const bool all = part == "all";
  if (backend != "cpu" && backend != "gpu" && backend != "all")
    throw Error("--backend '" + backend + "' is not allowed for the study; use cpu, gpu or all");
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir)) throw Error("--out-dir '" + out_dir + "' cannot be created");
  const fs::path dir(out_dir);
  g_quick = quick;
  // Every output is written under a temporary name and renamed into place
  // only when the whole study has succeeded.
  OutputSet outs;
  Image acc_rgb;
  std::string acc_name;
  if (!all) {
    // the leakage experiment builds its own scene
  } else if (!image_path.empty()) {
    acc_rgb = read_color(image_path);
    acc_name = image_path;
  } else {
    const std::string d = data_dir();
    if (d.empty())
      throw Error("no --image given and ../shared/data not found; give --image FILE (a real image in [0,1])");
    if (quick) {
      acc_name = d + "/middlebury2005_thirdsize/Art/view1.png";
      if (!fs::exists(acc_name)) throw Error(acc_name + " not found; give --image FILE (a real image in [0,1])");
      acc_rgb = read_color(acc_name);
    } else {
      acc_rgb = study_mosaic(d);
      acc_name = "1600x1120 mosaic of ../shared/data photographs";
    }
  }
  const Image acc_img = rgba(acc_rgb);

  std::unique_ptr<GpuContext> ctx;
  std::vector<StudyBackend> backends;
  if (backend != "gpu") backends.push_back({"cpu", nullptr, false});
  if (backend != "cpu") {
    ctx = std::make_unique<GpuContext>();  // throws with the reason
    const std::string r = ctx->info().renderer;
    const bool soft = ctx->info().software;
    backends.push_back({"gpu", ctx.get(), soft});
    std::fprintf(stderr, "brume study: GPU %s%s\n", r.c_str(), soft ? " (software: standard scheme limited to 300 passes)" : "");
  }
  const Scheme schemes[] = {Scheme::standard, Scheme::invariant, Scheme::invariant_exact};
  const Precision precs[] = {Precision::f32, Precision::f16};
  auto params = [](Scheme s, Precision pr, EdgeRate e = DiffusionParams{}.edge_rate) {
    DiffusionParams p;
    p.scheme = s;
    p.precision = pr;
    p.edge_rate = e;
    return p;
  };
  auto too_long = [&params](const StudyBackend& b, Scheme s, double sigma) {
    return b.software && s == Scheme::standard && plan_diffusion(params(s, Precision::f32), sigma).iterations > 300;
  };

  // ---- Accuracy (Fig. 6) ---------------------------------------------------
  const std::vector<double> acc_sigmas =
      quick ? std::vector<double>{2, 5, 10} : std::vector<double>{1.5, 2, 3, 4, 5, 6, 8, 10, 13, 16, 20, 25};
  std::vector<AccRow> acc_rows;
  if (all) {
    std::ostringstream acc;
    acc << "scheme,precision,backend,sigma,rms,iterations,spread\n";
    std::fprintf(stderr, "brume study: accuracy on %s (%dx%d)\n", acc_name.c_str(), acc_img.width, acc_img.height);
    auto emit = [&](const std::string& scheme, const std::string& prec, const std::string& bname, double sigma,
                    double rms, int iters, double spread) {
      acc << scheme << "," << prec << "," << bname << "," << sigma << "," << rms << "," << iters << "," << spread << "\n";
      acc_rows.push_back({scheme, prec, bname, sigma, rms, iters, spread});
      std::fprintf(stderr, "  %-15s %s %s sigma %5.1f: rms %.3e, %4d iterations, spread %.3f\n", scheme.c_str(),
                   prec.c_str(), bname.c_str(), sigma, rms, iters, spread);
    };
    for (double sigma : acc_sigmas) {
      const Image ref = gaussian(acc_img, std::sqrt(sigma * sigma - 1.0));
      const int border = static_cast<int>(std::ceil(4 * sigma));
      const Image map(acc_img.width, acc_img.height, 1, static_cast<float>(sigma));
      for (const StudyBackend& b : backends)
        for (Scheme s : schemes)
          for (Precision pr : precs) {
            if (too_long(b, s, sigma)) continue;
            Image f = acc_img;
            const DiffusionPlan plan = run_brume(b, f, map, sigma, params(s, pr));
            const double spread = impulse_spread(
                [&](Image& g, const Image& m) { run_brume(b, g, m, sigma, params(s, pr)); }, sigma);
            emit(to_string(s), to_string(pr), b.name, sigma, rms_rgb(f, ref, border), plan.iterations, spread);
          }
      {
        Image f = acc_img;
        peers::mipmap_blur(f, map, 1.0);
        emit("mipmap", "f32", "cpu", sigma, rms_rgb(f, ref, border), 0,
             impulse_spread([](Image& g, const Image& m) { peers::mipmap_blur(g, m, 1.0); }, sigma));
      }
      {
        Image f = acc_img;
        peers::gather_blur(f, map, 1.0);
        emit("gather", "f32", "cpu", sigma, rms_rgb(f, ref, border), 0,
             impulse_spread([](Image& g, const Image& m) { peers::gather_blur(g, m, 1.0); }, sigma));
      }
    }
    outs.write_text((dir / "accuracy.csv").string(), acc.str(), "--out-dir");
  }

  // ---- Speed (Fig. 7) -------------------------------------------------------
  const int W = quick ? 463 : 1600, H = quick ? 370 : 1120;
  const DemoScene scene = all ? render_demo_scene(W, H) : DemoScene{};  // the speed part only
  const Image big = rgba(scene.rgb);
  double rmax = 0;
  for (float r : scene.range.data)
    if (std::isfinite(r)) rmax = std::max(rmax, static_cast<double>(r));
  std::vector<SpeedRow> speed_rows;
  if (all) {
    std::ostringstream spd;
    spd << "method,precision,backend,sigma,seconds,iterations,map,runs\n";
    auto emit = [&](const std::string& method, const std::string& prec, const std::string& bname, double sigma,
                    Timed t, int iters, const std::string& map) {
      spd << method << "," << prec << "," << bname << "," << sigma << "," << t.seconds << "," << iters << "," << map
          << "," << t.runs << "\n";
      speed_rows.push_back({method, prec, bname, sigma, t.seconds, iters, map});
      std::fprintf(stderr, "  %-28s %s %s %-8s sigma %4.1f: %9.2f ms (%d iterations)\n", method.c_str(), prec.c_str(),
                   bname.c_str(), map.c_str(), sigma, t.seconds * 1e3, iters);
    };
    std::fprintf(stderr, "brume study: speed on %dx%d\n", W, H);
    for (double sigma : quick ? std::vector<double>{5, 10} : std::vector<double>{2, 5, 10, 15, 20, 25}) {
      const Image cmap(W, H, 1, static_cast<float>(sigma));
      Image vmap(W, H, 1);
      for (std::size_t i = 0; i < vmap.pixels(); ++i) {
        const float r = scene.range.data[i];
        const double rn = std::isfinite(r) ? std::min(r / rmax, 1.0) : 1.0;
        vmap.data[i] = static_cast<float>(1.0 + rn * std::sqrt(rn) * (sigma - 1.0));
      }
      // OpenCV GaussianBlur at the same sigma on RGBA float (the same bytes as brume).
      const cv::Mat src(H, W, CV_32FC4, const_cast<float*>(big.data.data()));
      cv::Mat dst;
      const double eff = std::sqrt(sigma * sigma - 1.0);
      emit("opencv-gaussianblur", "f32", "cpu", sigma, time_it([&] {
             cv::GaussianBlur(src, dst, cv::Size(0, 0), eff, eff, cv::BORDER_REFLECT);
             return -1.0;
           }),
           1, "constant");
      int exact_iters = 0;
      for (const StudyBackend& b : backends)
        for (Scheme s : schemes)
          for (Precision pr : precs)
            for (const char* mapname : {"constant", "varying"}) {
              const bool varying = std::string(mapname) == "varying";
              if (s == Scheme::standard && (varying || too_long(b, s, sigma) || (quick && (b.gpu || sigma > 5))))
                continue;  // hundreds of passes: the constant map is the paper's experiment
              if (s == Scheme::invariant && varying) continue;
              int iters = 0;
              const Timed t = time_it([&] {
                Image f = big;
                double gs = -1.0;
                iters = run_brume(b, f, varying ? vmap : cmap, sigma, params(s, pr), &gs).iterations;
                return b.gpu ? gs : -1.0;
              });
              if (s == Scheme::invariant_exact && !b.gpu) exact_iters = iters;
              emit("brume-" + to_string(s), to_string(pr), b.name, sigma, t, iters, mapname);
            }
      for (const char* mapname : {"constant", "varying"}) {
        const Image& m = std::string(mapname) == "varying" ? vmap : cmap;
        emit("mipmap", "f32", "cpu", sigma, time_it([&] {
               Image f = big;
               peers::mipmap_blur(f, m, 1.0);
               return -1.0;
             }),
             0, mapname);
        emit("gather", "f32", "cpu", sigma, time_it([&] {
               Image f = big;
               peers::gather_blur(f, m, 1.0);
               return -1.0;
             }),
             0, mapname);
      }
      // Streaming floor: the same bytes copied as many times as invariant-exact iterates.
      std::vector<float> a(big.data), bb(big.data.size());
      emit("memory-floor", "f32", "cpu", sigma, time_it([&] {
             for (int k = 0; k < exact_iters; ++k) std::memcpy(bb.data(), a.data(), a.size() * sizeof(float)), a.swap(bb);
             return -1.0;
           }),
           exact_iters, "constant");
    }
    outs.write_text((dir / "speed.csv").string(), spd.str(), "--out-dir");
  }

  // ---- Leakage across a depth edge -----------------------------------------
  const int n = quick ? 160 : 320;
  const double sfar = quick ? 10.0 : 25.0;
  const int q0 = n / 4, q1 = 3 * n / 4;  // the near square [q0, q1)^2
  Image scene_f(n, n, 4, 0.0f), smap(n, n, 1, static_cast<float>(sfar));
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const bool near = x >= q0 && x < q1 && y >= q0 && y < q1;
      scene_f.at(x, y, near ? 1 : 0) = 1.0f;
      scene_f.at(x, y, 3) = 1.0f;
      if (near) smap.at(x, y) = 1.0f;
    }
  std::vector<LeakRow> leak_rows;
  std::vector<std::pair<std::string, Image>> crops;
  {
    std::ostringstream lk;
    lk << "method,edge_rate,backend,sigma_far,into_near_mean,into_near_max,into_far_mean\n";
    std::fprintf(stderr, "brume study: leakage, near square on a far background at sigma %.0f\n", sfar);
    auto measure = [&](const std::string& method, const std::string& edge, const std::string& bname, const Image& g) {
      double rim = 0, rim_n = 0, nmax = 0, far = 0, far_n = 0;
      for (int y = 0; y < n; ++y)
        for (int x = 0; x < n; ++x) {
          const int dx = std::max(q0 - x, x - (q1 - 1)), dy = std::max(q0 - y, y - (q1 - 1));
          const int d = std::max(dx, dy);  // > 0 outside (Chebyshev distance), <= 0 inside
          if (d <= 0) {
            nmax = std::max(nmax, static_cast<double>(g.at(x, y, 0)));
            if (d > -2) rim += g.at(x, y, 0), ++rim_n;
          } else if (d <= sfar) {
            far += g.at(x, y, 1), ++far_n;
          }
        }
      lk << method << "," << edge << "," << bname << "," << sfar << "," << rim / rim_n << "," << nmax << ","
         << far / far_n << "\n";
      leak_rows.push_back({method, edge, bname, rim / rim_n, nmax, far / far_n});
      std::fprintf(stderr, "  %-15s %-8s %s: background in near rim %.4f (max %.4f), near colour in far ring %.4f\n",
                   method.c_str(), edge.c_str(), bname.c_str(), rim / rim_n, nmax, far / far_n);
    };
    for (const StudyBackend& b : backends)
      for (Scheme s : schemes)
        for (EdgeRate e : {EdgeRate::mean, EdgeRate::min, EdgeRate::harmonic}) {
          if (too_long(b, s, sfar)) continue;
          Image g = scene_f;
          run_brume(b, g, smap, sfar, params(s, Precision::f32, e));
          measure(to_string(s), to_string(e), b.name, g);
          if (!b.gpu && s != Scheme::invariant) crops.emplace_back(to_string(s) + "_" + to_string(e), g);
        }
    Image g = scene_f;
    peers::mipmap_blur(g, smap, 1.0);
    measure("mipmap", "-", "cpu", g);
    crops.emplace_back("mipmap", g);
    g = scene_f;
    peers::gather_blur(g, smap, 1.0);
    measure("gather", "-", "cpu", g);
    crops.emplace_back("gather", g);
    outs.write_text((dir / "leakage.csv").string(), lk.str(), "--out-dir");
  }

  // ---- Figures ---------------------------------------------------------------
  write_crops(outs, dir, crops, n, q0);
  if (all) write_summary(outs, dir, acc_rows, speed_rows, leak_rows, acc_name, acc_img, W, H, sfar);
  outs.commit();
  // The figures are matplotlib's (python/brume/plots.py), drawn from these files.
  std::fprintf(stderr, "brume study: wrote %s in %s\n",
               all ? "accuracy.csv, speed.csv, leakage.csv, leakage_crops/ and summary.md" : "leakage.csv and leakage_crops/",
               out_dir.c_str());
  std::fprintf(stderr, "brume study: draw the figures with: PYTHONPATH=%s python3 -m brume.plots %s\n", BRUME_PYTHON_DIR,
               out_dir.c_str());
  return 0;
}
