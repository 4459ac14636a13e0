// brume — image comparison: Morales eq. 3.14 histogram correlations and PSNR
// (see brume/compare.hpp for the definitions).
#include "brume/command.hpp"
#include "brume/compare.hpp"

#include <cstdio>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <unistd.h>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume/record.hpp"
#include "brume_opencv.hpp"

namespace fs = std::filesystem;

namespace brume {

namespace {

// Linear RGB -> 8-bit sRGB codes in a CV_8UC3 Mat (R, G, B order), counting
// the samples outside [0, 1] that the encoding clips. Rounds half up, as
// OpenImageIO does when brume writes an 8-bit file, so the codes are the
// ones `--bits 8` would store.
cv::Mat encode_srgb8(const Image& im, std::size_t& clipped) {
  cv::Mat m(im.height, im.width, CV_8UC3);
  clipped = 0;
  for (int y = 0; y < im.height; ++y) {
    unsigned char* row = m.ptr<unsigned char>(y);
    const float* src = im.row(y);
    for (int i = 0; i < im.width * 3; ++i) {
      const float v = src[i];
      if (v < 0.0f || v > 1.0f) ++clipped;
      const float e = linear_to_srgb(std::clamp(v, 0.0f, 1.0f));
      row[i] = static_cast<unsigned char>(std::lround(std::clamp(e, 0.0f, 1.0f) * 255.0f));
    }
  }
  return m;
}

struct Histograms {
  cv::Mat hs, v;
};

// The histograms of eq. 3.14, through OpenCV as the thesis computed them.
Histograms histograms(const cv::Mat& srgb8, const cv::Mat& mask) {
  cv::Mat hsv;
  cv::cvtColor(srgb8, hsv, cv::COLOR_RGB2HSV);  // 8-bit: H in [0, 180), S and V in [0, 256)
  Histograms h;
  const int hs_channels[] = {0, 1};
  const int hs_size[] = {kCompareHueBins, kCompareSaturationBins};
  const float h_range[] = {0.0f, 180.0f}, s_range[] = {0.0f, 256.0f};
  const float* hs_ranges[] = {h_range, s_range};
  cv::calcHist(&hsv, 1, hs_channels, mask, h.hs, 2, hs_size, hs_ranges, true, false);
  const int v_channel[] = {2};
  const int v_size[] = {kCompareValueBins};
  const float v_range[] = {0.0f, 256.0f};
  const float* v_ranges[] = {v_range};
  cv::calcHist(&hsv, 1, v_channel, mask, h.v, 1, v_size, v_ranges, true, false);
  return h;
}

double psnr_db(double mse, double peak) {
  return mse > 0.0 ? 10.0 * std::log10(peak * peak / mse) : std::numeric_limits<double>::infinity();
}

nlohmann::json db_json(double v) { return std::isinf(v) ? nlohmann::json("inf") : nlohmann::json(v); }

void check_json_path(const std::string& path) { check_output_dir(path, "--json"); }

}  // namespace

CompareResult compare_images(const Image& a, const Image& b, const Image* mask) {
  if (a.channels != 3 || b.channels != 3)
    throw Error("compare needs two RGB images, got " + std::to_string(a.channels) + " and " +
                std::to_string(b.channels) + " channels");
  if (a.width != b.width || a.height != b.height)
    throw Error("image A is " + a.size_string() + " but image B is " + b.size_string() +
                "; compare needs two images of the same size (resample or crop one)");
  if (mask && (mask->width != a.width || mask->height != a.height || mask->channels != 1))
    throw Error("the mask is " + mask->size_string() + " with " + std::to_string(mask->channels) +
                " channel(s) but the images are " + a.size_string() + "; it must be one channel of the same size");
  for (const Image* im : {&a, &b})
    for (std::size_t i = 0; i < im->data.size(); ++i)
      if (std::isnan(im->data[i]))
        throw Error(std::string("image ") + (im == &a ? "A" : "B") + " has NaN at pixel (" +
                    std::to_string(i / 3 % im->width) + ", " + std::to_string(i / 3 / im->width) +
                    "); compare needs colour at every pixel (mask the pixel out, or fill it)");

  CompareResult r;
  cv::Mat m8;  // calcHist's mask: CV_8U, non-zero = counted
  if (mask) {
    m8.create(a.height, a.width, CV_8U);
    for (int y = 0; y < a.height; ++y)
      for (int x = 0; x < a.width; ++x) m8.at<unsigned char>(y, x) = mask->at(x, y) != 0.0f ? 255 : 0;
  }

  // PSNR over the same pixels.
  const cv::Mat ea = encode_srgb8(a, r.clipped_a), eb = encode_srgb8(b, r.clipped_b);
  double se_lin = 0.0, se_8 = 0.0;
  for (int y = 0; y < a.height; ++y) {
    const float *pa = a.row(y), *pb = b.row(y);
    const unsigned char *ca = ea.ptr<unsigned char>(y), *cb = eb.ptr<unsigned char>(y);
    for (int x = 0; x < a.width; ++x) {
      if (mask && !m8.at<unsigned char>(y, x)) continue;
      ++r.pixels;
      for (int c = 0; c < 3; ++c) {
        const int k = x * 3 + c;
        const double d = static_cast<double>(pa[k]) - pb[k];
        const double d8 = static_cast<double>(ca[k]) - cb[k];
        se_lin += d * d;
        se_8 += d8 * d8;
      }
    }
  }
  if (r.pixels == 0)
    throw Error("the mask selects no pixel (every value is 0); non-zero mask pixels are the ones compared");
  const double n = 3.0 * static_cast<double>(r.pixels);
  r.mse_linear = se_lin / n;
  r.mse_srgb8 = se_8 / n;
  r.psnr_linear_db = psnr_db(r.mse_linear, 1.0);
  r.psnr_srgb8_db = psnr_db(r.mse_srgb8, 255.0);

  const Histograms ha = histograms(ea, m8), hb = histograms(eb, m8);
  r.hs_correlation = cv::compareHist(ha.hs, hb.hs, cv::HISTCMP_CORREL);
  r.v_correlation = cv::compareHist(ha.v, hb.v, cv::HISTCMP_CORREL);
  return r;
}

nlohmann::json compare_result_json(const CompareResult& r) {
  return {{"hue_saturation_correlation", r.hs_correlation},
          {"brightness_correlation", r.v_correlation},
          {"psnr_linear_db", db_json(r.psnr_linear_db)},
          {"psnr_srgb8_db", db_json(r.psnr_srgb8_db)},
          {"mse_linear", r.mse_linear},
          {"mse_srgb8", r.mse_srgb8},
          {"pixels_compared", r.pixels},
          {"clipped_samples_a", r.clipped_a},
          {"clipped_samples_b", r.clipped_b},
          {"method",
           {{"correlation", "Morales eq. 3.14 = OpenCV compareHist HISTCMP_CORREL"},
            {"histogram_colour_space",
             "HSV (OpenCV cvtColor COLOR_RGB2HSV, 8-bit: H in [0,180), S and V in [0,256)) of 8-bit sRGB-encoded "
             "colour; linear values outside [0,1] clipped before encoding"},
            {"hue_saturation_bins", {kCompareHueBins, kCompareSaturationBins}},
            {"hue_range", {0, 180}},
            {"saturation_range", {0, 256}},
            {"brightness_bins", kCompareValueBins},
            {"brightness_range", {0, 256}},
            {"psnr_linear", "10 log10(1 / MSE) on linear float RGB, peak 1, all three channels"},
            {"psnr_srgb8", "10 log10(255^2 / MSE) on the 8-bit sRGB codes, all three channels"},
            {"psnr_infinite", "identical images: MSE 0, PSNR written as the string \"inf\""}}}};
}

const ParamTable<CompareJob>& compare_job_table() {
  static const ParamTable<CompareJob> t = [] {
    ParamTable<CompareJob> d("compare");
    d.text("a", &CompareJob::a, "image A (PNG/TIFF/JPEG: sRGB-encoded; EXR/PFM/HDR: linear)")
        .reads_file()
        .text("a-layer", &CompareJob::a_layer,
              "the layer of A in a file with layers (NAME.R, NAME.G, NAME.B of a multilayer OpenEXR)")
        .text("b", &CompareJob::b, "image B, the same size as A")
        .reads_file()
        .text("b-layer", &CompareJob::b_layer, "the layer of B in a file with layers")
        .text("mask", &CompareJob::mask, "grey image of the same size: non-zero pixels are compared (default: all)")
        .reads_file()
        .text("json", &CompareJob::json, "write the result, the method and the inputs as JSON");
    return d;
  }();
  return t;
}

nlohmann::json run_compare_job(const CompareJob& job, const RunContext& ctx) {
  compare_job_table().validate(job);
  if (job.a.empty() || job.b.empty()) throw Error("compare needs two images: give --a FILE and --b FILE");
  if (!job.json.empty()) check_json_path(job.json);
  FileInfo ia, ib, im;
  ColorRead ha, hb;
  ha.layer = job.a_layer, ha.layer_flag = "--a-layer";
  hb.layer = job.b_layer, hb.layer_flag = "--b-layer";
  const Image a = read_color(job.a, ha, &ia);
  const Image b = read_color(job.b, hb, &ib);
  if (a.width != b.width || a.height != b.height)
    throw Error("--a '" + job.a + "' is " + a.size_string() + " but --b '" + job.b + "' is " + b.size_string() +
                "; compare needs two images of the same size (resample or crop one)");
  nlohmann::json rec = run_record_header("compare", ctx.argv);
  rec["job"] = compare_job_table().to_json(job);
  rec["inputs"]["a"] = file_record(job.a, ia, a);
  rec["inputs"]["b"] = file_record(job.b, ib, b);
  Image mask;
  if (!job.mask.empty()) {
    mask = read_scalar(job.mask, "", &im);
    if (mask.width != a.width || mask.height != a.height)
      throw Error("--mask '" + job.mask + "' is " + mask.size_string() + " but --a '" + job.a + "' and --b '" + job.b +
                  "' are " + a.size_string() + "; the mask must be the images' size");
    rec["inputs"]["mask"] = file_record(job.mask, im, mask);
  }
  CompareResult r;
  try {
    r = compare_images(a, b, job.mask.empty() ? nullptr : &mask);
  } catch (const Error& e) {
    throw Error("--a '" + job.a + "', --b '" + job.b + "'" + (job.mask.empty() ? "" : ", --mask '" + job.mask + "'") +
                ": " + e.what());
  }
  rec["result"] = compare_result_json(r);
  if (!job.json.empty()) {
    OutputSet outs;
    outs.write_text(job.json, rec.dump(2) + "\n", "--json");
    outs.commit();
  }
  return rec;
}

namespace {
std::string db_text(const nlohmann::json& v) {
  if (v.is_string()) return v.get<std::string>() + " dB (identical)";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f dB", v.get<double>());
  return buf;
}
}  // namespace

CommandDef compare_command() {
  return make_command<CompareJob>({
      .name = "compare",
      .cli = "compare",
      .summary = "compare two images: HSV histogram correlations (Morales eq. 3.14) and PSNR",
      .table = &compare_job_table(),
      .run = [](const CompareJob& j, const ExecOptions&, const RunContext& ctx) { return run_compare_job(j, ctx); },
      .report = [](const CompareJob&, const nlohmann::json& result) {
        const nlohmann::json& r = result["result"];
        // The result is this command's product: stdout, not stderr.
        std::printf("pixels compared            %zu\n"
                    "hue-saturation correlation %.6f  (eq. 3.14, HSV of 8-bit sRGB, H x S = %d x %d bins)\n"
                    "brightness correlation     %.6f  (eq. 3.14, V, %d bins)\n"
                    "PSNR linear RGB            %s  (peak 1)\n"
                    "PSNR 8-bit sRGB            %s  (peak 255)\n",
                    r["pixels_compared"].get<std::size_t>(), r["hue_saturation_correlation"].get<double>(),
                    kCompareHueBins, kCompareSaturationBins, r["brightness_correlation"].get<double>(),
                    kCompareValueBins, db_text(r["psnr_linear_db"]).c_str(), db_text(r["psnr_srgb8_db"]).c_str());
        const auto ca = r["clipped_samples_a"].get<std::size_t>(), cb = r["clipped_samples_b"].get<std::size_t>();
        if (ca || cb) std::printf("clipped to [0,1] for the 8-bit encoding: %zu samples of A, %zu of B\n", ca, cb);
      },
  });
}

}  // namespace brume
