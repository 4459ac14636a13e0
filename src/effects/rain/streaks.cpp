// brume — the camera pass of falling particles (effects/rain/streaks.hpp): rain's, moved here
// unchanged so that snow's flakes take the same steps (issue #58).
#include "effects/rain/streaks.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

#include "brume/error.hpp"
#include "brume/io.hpp"

namespace brume {

namespace {
constexpr std::size_t kAhead = 8;  // how many streaks ahead a tile's loop fetches
constexpr double kStreakInf = std::numeric_limits<double>::infinity();
constexpr double kStreakPi = 3.14159265358979323846;
}  // namespace

StreakBoxMean::StreakBoxMean(ConstImageView rgb, int h)
    : w_(rgb.width()), h_(rgb.height()), r_(h), s_((w_ + 1) * (h_ + 1) * 3, 0.0) {
  for (int y = 0; y < h_; ++y)
    for (int x = 0; x < w_; ++x)
      for (int c = 0; c < 3; ++c) at(x + 1, y + 1, c) = rgb.at(x, y, c) + at(x, y + 1, c) + at(x + 1, y, c) - at(x, y, c);
}

double StreakBoxMean::mean(int x, int y, int c) const {
  const int x0 = std::max(0, x - r_), x1 = std::min(w_, x + r_ + 1), y0 = std::max(0, y - r_),
            y1 = std::min(h_, y + r_ + 1);
  const double s = get(x1, y1, c) - get(x0, y1, c) - get(x1, y0, c) + get(x0, y0, c);
  return s / (static_cast<double>(x1 - x0) * (y1 - y0));
}

double StreakBoxMean::total(int c) const { return get(w_, h_, c) / (static_cast<double>(w_) * h_); }

Image streak_background(const CameraRainScene& s, const std::function<double(double, double)>& front_tau,
                        double sigma_total, int nt, Image* transmission) {
  const int W = s.rgb.width(), H = s.rgb.height();
  const double fx = s.k.fx, fy = s.k.fy, cx = s.k.cx, cy = s.k.cy;
  const auto ray_cos = [&](double u, double v) {
    const double x = (u - cx) / fx, y = (v - cy) / fy;
    return 1.0 / std::sqrt(x * x + y * y + 1.0);
  };
  Image tau0(W, H, 1);
#pragma omp parallel for num_threads(nt) schedule(static)
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float r = s.range.at(x, y);
      float t = 1.0f;
      if (s.analytic) {
        // Unknown range (the sky) lies beyond the unbounded media: transmission 0 when there are any.
        t = streak_range_known(r) ? static_cast<float>(std::exp(-front_tau(r, ray_cos(x, y))))
                                  : (sigma_total > 0.0 ? 0.0f : 1.0f);
        if (!s.sky_weight.empty()) {
          const float w = s.sky_weight.at(x, y);
          const float t_sky = sigma_total > 0.0 ? 0.0f : 1.0f;
          t = w <= 0.0f ? t : w >= 1.0f ? t_sky : (1.0f - w) * t + w * t_sky;
        }
      }
      tau0.data[static_cast<std::size_t>(y) * W + x] = t;
    }
  Image out;
  if (s.composite) {
    out = s.composite(tau0);
  } else {
    out = Image(W, H, 3);
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * W + x;
        const float t = tau0.data[i];
        for (int c = 0; c < 3; ++c) out.data[i * 3 + c] = t * s.rgb.at(x, y, c) + (1.0f - t) * s.airlight[c];
      }
  }
  if (transmission) *transmission = tau0;
  return out;
}

StreakSlabs frustum_streaks(const RainField& field, const std::function<double(double)>& threshold_mm,
                                    double z_near, double z_split, const std::function<double(double, double)>& grow_m,
                                    const StreakCamera& cam, int nt,
                                    const std::function<bool(const Vec3&, double, Streak&)>& make, std::size_t& cells_out,
                                    std::size_t& seen_out) {
  const int W = cam.width, H = cam.height;
  const double fx = cam.fx, fy = cam.fy, cx = cam.cx, cy = cam.cy;
  const double xa = (-0.5 - cx) / fx, xb = (W - 0.5 - cx) / fx, ya = (-0.5 - cy) / fy, yb = (H - 0.5 - cy) / fy;
  const double c = kRainCellM;
  const std::int64_t ix0 = static_cast<std::int64_t>(std::floor(z_near / c));
  const std::int64_t ix1 = static_cast<std::int64_t>(std::floor(z_split / c));
  const std::size_t slabs = static_cast<std::size_t>(ix1 - ix0 + 1);
  StreakSlabs found(slabs);
  std::vector<std::size_t> seen(slabs, 0), cells(slabs, 0);
  // The far slabs first, one at a time (the widest: the last taken are the cheapest, so that no
  // thread is left with a far slab at the end); each slab's list is its own, whoever draws it.
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
  for (std::int64_t back = 0; back <= ix1 - ix0; ++back) {
    const std::int64_t ix = ix1 - back;
    const std::size_t si = static_cast<std::size_t>(ix - ix0);
    const double z0 = std::max(static_cast<double>(ix) * c, z_near), z1 = static_cast<double>(ix + 1) * c;
    if (!(z0 < z_split)) continue;
    const double m = field.measure_above(threshold_mm(z0));
    if (!(m > 0.0)) continue;
    // The slab's lateral extent: the frustum widened by the particles' motion and their kernel.
    const double grow = grow_m(z0, z1);
    const double xlo = std::min(xa * z0, xa * z1) - grow, xhi = std::max(xb * z0, xb * z1) + grow;
    const double ylo = std::min(ya * z0, ya * z1) - grow, yhi = std::max(yb * z0, yb * z1) + grow;
    // Vehicle frame: y = −x_cv, z = −y_cv.
    const std::int64_t jy0 = static_cast<std::int64_t>(std::floor(-xhi / c)),
                       jy1 = static_cast<std::int64_t>(std::floor(-xlo / c));
    const std::int64_t jz0 = static_cast<std::int64_t>(std::floor(-yhi / c)),
                       jz1 = static_cast<std::int64_t>(std::floor(-ylo / c));
    std::vector<Streak>& list = found[si];
    // Room for the slab's mean count of drops and four standard deviations (a Poisson count), up
    // to 2^22 of them: the list seldom grows, whose copies of large lists cost more than the drawing.
    const double mean = m * static_cast<double>(jy1 - jy0 + 1) * static_cast<double>(jz1 - jz0 + 1);
    list.reserve(static_cast<std::size_t>(std::min(mean + 4.0 * std::sqrt(mean) + 16.0, 4194304.0)));
    // A cell holds a drop within measure m iff its first unit exponential −ln(1 − u) <= m: a first
    // draw u above 1 − e^{−m(1 + 1e−9)} cannot (the margin far above the logarithms' rounding),
    // and the cell is passed over without them; the column's hash is taken once for its cells.
    const double u_max = -std::expm1(-m * (1.0 + 1e-9)) + 1e-15;
    for (std::int64_t jy = jy0; jy <= jy1; ++jy) {
      const std::uint64_t column = field.column_hash(ix, jy);
      for (std::int64_t jz = jz0; jz <= jz1; ++jz) {
        ++cells[si];
        const std::uint64_t h = RainField::cell_hash(column, jz);
        if (RainField::first_unit(h) > u_max) continue;
        field.for_each_drop_hashed(RainCell{ix, jy, jz}, h, m, [&](const Vec3& at, double sm) {
          ++seen[si];
          const double d_mm = field.diameter_mm(sm);
          if (d_mm < threshold_mm(at.x)) return;
          Streak k;
          if (!make(at, d_mm, k)) return;
          k.order = list.size();
          list.push_back(k);
        });
      }
    }
  }
  std::size_t order = 0;
  for (std::size_t i = 0; i < slabs; ++i) {
    cells_out += cells[i];
    seen_out += seen[i];
    for (Streak& k : found[i]) k.order = order++;
  }
  return found;
}

StreakSlabs moving_frustum_streaks(const RainField& field, const std::function<double(double)>& threshold_mm,
                                   double z_near, double z_split, const std::function<double(double, double)>& grow_m,
                                   const StreakCamera& cam, int nt, const StreakPose& pose, const Vec3& wind,
                                   const std::function<double(double)>& fall_m_s, double d_max_mm,
                                   const std::function<double(double)>& d_below,
                                   const std::function<bool(const Vec3&, double, Streak&)>& make,
                                   std::size_t& cells_out, std::size_t& seen_out) {
  const int W = cam.width, H = cam.height;
  const double xa = (-0.5 - cam.cx) / cam.fx, xb = (W - 0.5 - cam.cx) / cam.fx, ya = (-0.5 - cam.cy) / cam.fy,
               yb = (H - 0.5 - cam.cy) / cam.fy;
  const double c = kRainCellM, t = pose.t_s;
  const Mat3& R = pose.world_from_camera.rotation;
  const Vec3& O = pose.world_from_camera.translation;
  const Mat3 Rt = R.transposed();
  const std::int64_t ix0 = static_cast<std::int64_t>(std::floor(z_near / c));
  const std::int64_t ix1 = static_cast<std::int64_t>(std::floor(z_split / c));
  const std::size_t slabs = static_cast<std::size_t>(ix1 - ix0 + 1);
  // The frustum in pieces (depth steps of a brick, 8 x 4 across the image), each piece's corners in
  // the world widened by its lateral margin (√3 of it: a margin along the camera's axes, any world
  // axis), marking the brick columns (B x B cells, shifted back by the drift w·t) and the heights
  // their particles must land at.
  constexpr int B = 4, nU = 8, nV = 4;
  const double bm = B * c, sx = wind.x * t, sy = wind.y * t;
  struct Box {
    double lo[3], hi[3];
  };
  std::vector<Box> pieces;
  for (double z0 = z_near; z0 < z_split; z0 += bm) {
    const double z1 = std::min(z_split, z0 + bm), g = grow_m(z0, z1) * std::sqrt(3.0);
    for (int iu = 0; iu < nU; ++iu)
      for (int iv = 0; iv < nV; ++iv) {
        Box b{{kStreakInf, kStreakInf, kStreakInf}, {-kStreakInf, -kStreakInf, -kStreakInf}};
        for (int corner = 0; corner < 8; ++corner) {
          const double z = corner & 1 ? z1 : z0;
          const double xn = xa + (xb - xa) * (iu + ((corner >> 1) & 1)) / nU;
          const double yn = ya + (yb - ya) * (iv + ((corner >> 2) & 1)) / nV;
          const Vec3 q = R * Vec3{z, -xn * z, -yn * z};  // the camera's field axes into the world
          const double w[3] = {q.x + O.x, q.y + O.y, q.z + O.z};
          for (int a = 0; a < 3; ++a) b.lo[a] = std::min(b.lo[a], w[a] - g), b.hi[a] = std::max(b.hi[a], w[a] + g);
        }
        pieces.push_back(b);
      }
  }
  double lo[2] = {kStreakInf, kStreakInf}, hi[2] = {-kStreakInf, -kStreakInf};
  for (const Box& b : pieces)
    for (int a = 0; a < 2; ++a) lo[a] = std::min(lo[a], b.lo[a]), hi[a] = std::max(hi[a], b.hi[a]);
  const std::int64_t gx0 = static_cast<std::int64_t>(std::floor((lo[0] - sx) / bm)),
                     gy0 = static_cast<std::int64_t>(std::floor((lo[1] - sy) / bm));
  const std::int64_t gnx = static_cast<std::int64_t>(std::floor((hi[0] - sx) / bm)) - gx0 + 1,
                     gny = static_cast<std::int64_t>(std::floor((hi[1] - sy) / bm)) - gy0 + 1;
  std::vector<std::int64_t> column(static_cast<std::size_t>(2 * gnx * gny));
  for (std::size_t k = 0; k < column.size(); k += 2) column[k] = INT64_MAX, column[k + 1] = INT64_MIN;
  for (const Box& b : pieces) {
    const std::int64_t cz0 = static_cast<std::int64_t>(std::floor(b.lo[2] / c)),
                       cz1 = static_cast<std::int64_t>(std::floor(b.hi[2] / c));
    const std::int64_t x0 = static_cast<std::int64_t>(std::floor((b.lo[0] - sx) / bm)) - gx0,
                       x1 = static_cast<std::int64_t>(std::floor((b.hi[0] - sx) / bm)) - gx0,
                       y0 = static_cast<std::int64_t>(std::floor((b.lo[1] - sy) / bm)) - gy0,
                       y1 = static_cast<std::int64_t>(std::floor((b.hi[1] - sy) / bm)) - gy0;
    for (std::int64_t gx = std::max<std::int64_t>(0, x0); gx <= std::min(gnx - 1, x1); ++gx)
      for (std::int64_t gy = std::max<std::int64_t>(0, y0); gy <= std::min(gny - 1, y1); ++gy) {
        std::int64_t* z = &column[static_cast<std::size_t>(2 * (gx * gny + gy))];
        z[0] = std::min(z[0], cz0), z[1] = std::max(z[1], cz1);
      }
  }
  // Each brick row's particles (slab, streak) in their order, whoever draws them.
  struct Found {
    std::size_t slab;
    Streak k;
  };
  std::vector<std::vector<Found>> rows(static_cast<std::size_t>(gnx));
  std::vector<std::size_t> cells(static_cast<std::size_t>(gnx), 0), seen(static_cast<std::size_t>(gnx), 0);
  const Vec3 fwd{R.m[0][0], R.m[1][0], R.m[2][0]};  // the camera's depth axis in the world
  const double f_hi = fall_m_s(d_max_mm) - wind.z;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
  for (std::int64_t gx = 0; gx < gnx; ++gx) {
    std::vector<std::pair<std::int64_t, std::int64_t>> spans;
    std::vector<Found>& list = rows[static_cast<std::size_t>(gx)];
    for (std::int64_t gy = 0; gy < gny; ++gy) {
      const std::int64_t* zc = &column[static_cast<std::size_t>(2 * (gx * gny + gy))];
      if (zc[0] > zc[1]) continue;
      const double z_lo = static_cast<double>(zc[0]) * c, z_hi = static_cast<double>(zc[1] + 1) * c;
      for (std::int64_t ix = (gx0 + gx) * B; ix < (gx0 + gx) * B + B; ++ix)
        for (std::int64_t iy = (gy0 + gy) * B; iy < (gy0 + gy) * B + B; ++iy) {
          // The landing box (the cell shifted by the drift, the column's heights): its nearest depth
          // gives the smallest diameter drawn there (D_t non-decreasing in z).
          const double blo[3] = {static_cast<double>(ix) * c + sx - O.x, static_cast<double>(iy) * c + sy - O.y,
                                 z_lo - O.z};
          const double bhi[3] = {blo[0] + c, blo[1] + c, z_hi - O.z};
          const double f3[3] = {fwd.x, fwd.y, fwd.z};
          double dmin = 0.0, dmax = 0.0;
          for (int a = 0; a < 3; ++a)
            dmin += std::min(f3[a] * blo[a], f3[a] * bhi[a]), dmax += std::max(f3[a] * blo[a], f3[a] * bhi[a]);
          if (dmax < z_near || dmin >= z_split) continue;
          const double thr = threshold_mm(std::max(dmin, z_near));
          const double m_col = field.measure_above(thr);
          if (!(m_col > 0.0)) continue;
          const double f_lo = fall_m_s(thr) - wind.z;  // the slowest fall (less w_z) drawn here
          spans.clear();
          if (t == 0.0) spans.push_back({zc[0], zc[1]});
          else falling_source_spans(z_lo, z_hi, f_lo, f_hi, t, spans);
          const std::uint64_t col = field.column_hash(ix, iy);
          // A cell holds a particle within measure m iff its first unit draw u <= 1 − e^{−m} (as
          // frustum_streaks): the column's measure bounds every cell's, and only a cell that passes
          // it pays for its own (the fall that can bring its particles here).
          const double u_col = -std::expm1(-m_col * (1.0 + 1e-9)) + 1e-15;
          for (const auto& [iz0, iz1] : spans)
            for (std::int64_t iz = iz0; iz <= iz1; ++iz) {
              ++cells[static_cast<std::size_t>(gx)];
              const std::uint64_t h = RainField::cell_hash(col, iz);
              const double u = RainField::first_unit(h);
              if (u > u_col) continue;
              double m = m_col;
              if (t != 0.0) {
                double f;
                if (!falling_min_speed(iz, z_lo, z_hi, f_lo, f_hi, t, f)) continue;
                if (d_below) m = field.measure_above(std::max(thr, d_below(f + wind.z)));
                if (u > -std::expm1(-m * (1.0 + 1e-9)) + 1e-15) continue;
              }
              field.for_each_drop_hashed(RainCell{ix, iy, iz}, h, m, [&](const Vec3& at0, double sm) {
                ++seen[static_cast<std::size_t>(gx)];
                const double d_mm = field.diameter_mm(sm);
                const Vec3 p = falling_at(at0, fall_m_s(d_mm), t, wind);
                const Vec3 q = Rt * Vec3{p.x - O.x, p.y - O.y, p.z - O.z};
                if (!(q.x >= z_near && q.x < z_split) || d_mm < threshold_mm(q.x)) return;
                Found found;
                if (!make(q, d_mm, found.k)) return;
                const std::int64_t si = static_cast<std::int64_t>(std::floor(q.x / c)) - ix0;
                found.slab = static_cast<std::size_t>(std::min<std::int64_t>(std::max<std::int64_t>(si, 0),
                                                                             static_cast<std::int64_t>(slabs) - 1));
                list.push_back(found);
              });
            }
        }
    }
  }
  StreakSlabs out(slabs);
  std::size_t order = 0;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    cells_out += cells[r];
    seen_out += seen[r];
    for (Found& f : rows[r]) out[f.slab].push_back(f.k);
  }
  for (std::vector<Streak>& slab : out)
    for (Streak& k : slab) k.order = order++;
  return out;
}

nlohmann::json streak_pose_files(const std::string& poses, const std::string& kitti_calib) {
  nlohmann::json files = nlohmann::json::object();
  if (poses.empty()) return files;
  files["poses"] = {{"path", poses}, {"sha256", sha256_file(poses)}};
  if (!kitti_calib.empty()) files["kitti_calib"] = {{"path", kitti_calib}, {"sha256", sha256_file(kitti_calib)}};
  return files;
}

double streak_grow_m(double z0, double z1, double d_max_mm, double motion_m, const StreakLens& lens,
                     const StreakCamera& cam) {
  const double kpx = 3.0 * std::sqrt(std::pow(lens.blur_px(z0) / 4.0, 2) + std::pow(lens.blur_px(z1) / 4.0, 2) +
                                     std::pow(cam.fx * d_max_mm * 1e-3 / z0 / 4.0, 2)) +
                     2.0;
  return motion_m + kpx * z1 / std::min(cam.fx, cam.fy);
}

bool place_streak(Streak& k, const Vec3& at, double d_mm, const double u[3], const StreakLens& lens, double T,
                  double z_clip, const StreakCamera& cam) {
  const double z = at.x;
  k.c[0] = -at.y, k.c[1] = -at.z, k.c[2] = at.x;
  k.u[0] = u[0], k.u[1] = u[1], k.u[2] = u[2];
  const double r = std::sqrt(k.c[0] * k.c[0] + k.c[1] * k.c[1] + z * z);
  const double dm = d_mm * 1e-3;
  k.area = kStreakPi / 4.0 * dm * dm * cam.fx * cam.fy;
  const double dpx = cam.fx * dm / z, b = lens.blur_px(z);
  k.sigma_px = std::sqrt(dpx * dpx + b * b) / 4.0;
  k.range = r;
  return bound_streak(k, T, z_clip, cam);
}

void check_streak_scene(const CameraRainScene& s, const std::string& effect) {
  const int W = s.rgb.width(), H = s.rgb.height();
  if (s.rgb.channels() != 3)
    throw Error(effect + " needs an RGB image, got " + std::to_string(s.rgb.channels()) + " channels");
  if (s.range.channels() != 1 || s.range.width() != W || s.range.height() != H)
    throw Error("the range map " + s.range.size_string() + " does not match the image " + s.rgb.size_string() +
                "; they must be the same size");
  if (!s.sky_weight.empty() && (s.sky_weight.width() != W || s.sky_weight.height() != H))
    throw Error("internal: the sky weight is " + s.sky_weight.size_string() + ", the image " + s.rgb.size_string());
}

bool bound_streak(Streak& k, double T, double z_clip, const StreakCamera& cam) {
  const int W = cam.width, H = cam.height;
  // The part of the exposure in front of the camera (z >= z_clip).
  k.t0 = -T / 2.0, k.t1 = T / 2.0;
  if (k.u[2] != 0.0) {
    const double tc = (z_clip - k.c[2]) / k.u[2];  // z(tc) = z_clip
    if (k.u[2] < 0.0) k.t1 = std::min(k.t1, tc);
    else k.t0 = std::max(k.t0, tc);
  }
  if (!(k.t1 > k.t0)) return false;
  // Its rows over the exposure (a straight path: the ends bound it), widened by the kernel.
  double vmin = kStreakInf, vmax = -kStreakInf, umin = kStreakInf, umax = -kStreakInf;
  for (double t : {k.t0, k.t1}) {
    const double zz = k.c[2] + k.u[2] * t;
    const double uu = cam.fx * (k.c[0] + k.u[0] * t) / zz + cam.cx, vv = cam.fy * (k.c[1] + k.u[1] * t) / zz + cam.cy;
    vmin = std::min(vmin, vv), vmax = std::max(vmax, vv), umin = std::min(umin, uu), umax = std::max(umax, uu);
  }
  const double kr = 3.0 * k.sigma_px + 1.0;
  if (umax + kr < -0.5 || umin - kr > W - 0.5 || vmax + kr < -0.5 || vmin - kr > H - 0.5) return false;
  k.v_lo = static_cast<int>(std::max(0.0, std::floor(vmin - kr)));
  k.v_hi = static_cast<int>(std::min(H - 1.0, std::ceil(vmax + kr)));
  k.u_lo = static_cast<int>(std::max(0.0, std::floor(umin - kr)));
  k.u_hi = static_cast<int>(std::min(W - 1.0, std::ceil(umax + kr)));
  return true;
}

namespace {

// The permutation that lists the streaks far to near, ties by their order (the same as a
// comparison sort by range descending, then order ascending): a least-significant-digit radix sort
// (stable, three digits of 11 bits) of `key`, each streak's range rounded to single precision,
// its bits complemented (a positive float's bits order as its value; the rounding keeps the
// order, but not every difference), over the streaks listed by their order; then each run of
// equal keys (few, and short) sorted by the exact ranges, stably.
// `listed`: every streak's order is its index and its range positive and finite (as the pass
// draws them); else the comparison sort.
std::vector<std::uint32_t> far_to_near(const std::vector<const Streak*>& drops, std::vector<std::uint32_t> key,
                                       bool listed) {
  const std::size_t n = drops.size();
  std::vector<std::uint32_t> idx(n), tmp(n);
  for (std::size_t i = 0; i < n; ++i) idx[i] = static_cast<std::uint32_t>(i);
  const auto exact = [&](std::uint32_t a, std::uint32_t b) { return drops[a]->range > drops[b]->range; };
  if (!listed) {
    std::stable_sort(idx.begin(), idx.end(),
                     [&](std::uint32_t a, std::uint32_t b) { return drops[a]->order < drops[b]->order; });
    std::stable_sort(idx.begin(), idx.end(), exact);
    return idx;
  }
  constexpr int kBits = 11, kDigits = 3;
  constexpr std::uint32_t kMask = (1u << kBits) - 1;
  std::vector<std::uint32_t> count(static_cast<std::size_t>(kDigits) << kBits, 0u), key_tmp(n);
  for (std::size_t i = 0; i < n; ++i)
    for (int d = 0; d < kDigits; ++d) ++count[(static_cast<std::size_t>(d) << kBits) + ((key[i] >> (d * kBits)) & kMask)];
  for (int d = 0; d < kDigits && n > 0; ++d) {
    std::uint32_t* c = &count[static_cast<std::size_t>(d) << kBits];
    if (c[(key[0] >> (d * kBits)) & kMask] == n) continue;  // one digit: the pass keeps the order
    std::uint32_t run = 0;
    for (std::size_t b = 0; b <= kMask; ++b) {
      const std::uint32_t k = c[b];
      c[b] = run;
      run += k;
    }
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t at = c[(key[i] >> (d * kBits)) & kMask]++;
      key_tmp[at] = key[i], tmp[at] = idx[i];
    }
    key.swap(key_tmp), idx.swap(tmp);
  }
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i + 1;
    while (j < n && key[j] == key[i]) ++j;
    for (std::size_t a = i + 1; a < j; ++a)  // an insertion sort: stable, and the runs are short
      for (std::size_t b = a; b > i && exact(idx[b], idx[b - 1]); --b) std::swap(idx[b], idx[b - 1]);
    i = j;
  }
  return idx;
}

}  // namespace

// The streaks binned tile by tile (StreakBins): they stay where they were drawn; their order far
// to near is a radix sort's permutation, the tiles' lists one array (counted, then filled).
StreakBins bin_streaks(const StreakSlabs& slabs, const StreakCamera& cam, int kTileW, int kTileH, int nt) {
  StreakBins bins;
  std::vector<const Streak*>& drops = bins.drops;
  {
    std::size_t n = 0;
    for (const std::vector<Streak>& s : slabs) n += s.size();
    if (n > std::numeric_limits<std::uint32_t>::max())
      throw Error("internal: " + std::to_string(n) + " streaks, more than the splat's 32-bit lists hold");
    drops.reserve(n);
    for (const std::vector<Streak>& s : slabs)
      for (const Streak& k : s) drops.push_back(&k);
  }
  const std::size_t n = drops.size();
  const int W = cam.width, H = cam.height;
  const int tiles_x = (W + kTileW - 1) / kTileW, tiles_y = (H + kTileH - 1) / kTileH;
  const std::size_t n_tiles = static_cast<std::size_t>(tiles_x) * tiles_y;
  bins.tiles_x = tiles_x, bins.tiles_y = tiles_y;
  bins.first.assign(n_tiles + 1, 0);
  if (n == 0) return bins;
  std::vector<std::size_t>& first = bins.first;
  // Each streak's sort key, tiles and path length, and the tiles' counts, in one pass over the
  // streaks as they lie in memory (the passes far to near below read these, not the streaks).
  struct Span {
    std::uint16_t tx0, tx1, ty0, ty1;
  };
  if (tiles_x > 65535 || tiles_y > 65535)
    throw Error("internal: " + std::to_string(W) + "x" + std::to_string(H) + " is more tiles than the splat counts");
  std::vector<std::uint32_t> key(n);
  std::vector<Span> span(n);
  std::vector<double> path(n);
  // Each thread counts into its own row and the rows are summed after the region (no critical
  // section or reduction: LLVM's OpenMP runtime under ThreadSanitizer crashed in the critical
  // section's end when batch frames ran this region from several threads at once).
  const std::size_t rows = static_cast<std::size_t>(std::max(1, nt));
  std::vector<std::size_t> counts(rows * n_tiles, 0);
  std::vector<unsigned char> listed_by(rows, 1);
#pragma omp parallel num_threads(nt)
  {
    const std::size_t tid = static_cast<std::size_t>(omp_get_thread_num());
    std::size_t* const count = counts.data() + tid * n_tiles;
    bool listed = true;
#pragma omp for schedule(static)
    for (std::size_t i = 0; i < n; ++i) {
      const Streak& k = *drops[i];
      listed = listed && k.order == i && k.range > 0.0 && std::isfinite(k.range);
      const float r = static_cast<float>(k.range);
      std::uint32_t bits;
      std::memcpy(&bits, &r, sizeof bits);
      key[i] = ~bits;
      const Span sp = {static_cast<std::uint16_t>(std::max(0, k.u_lo - 1) / kTileW),
                       static_cast<std::uint16_t>(std::min(W - 1, k.u_hi + 1) / kTileW),
                       static_cast<std::uint16_t>(std::max(0, k.v_lo - 1) / kTileH),
                       static_cast<std::uint16_t>(std::min(H - 1, k.v_hi + 1) / kTileH)};
      span[i] = sp;
      for (int ty = sp.ty0; ty <= sp.ty1; ++ty)
        for (int tx = sp.tx0; tx <= sp.tx1; ++tx) ++count[static_cast<std::size_t>(ty) * tiles_x + tx];
      double e[2][2];
      for (int j = 0; j < 2; ++j) {
        const double t = j ? k.t1 : k.t0, pz = k.c[2] + k.u[2] * t;
        e[j][0] = cam.fx * (k.c[0] + k.u[0] * t) / pz, e[j][1] = cam.fy * (k.c[1] + k.u[1] * t) / pz;
      }
      path[i] = std::hypot(e[1][0] - e[0][0], e[1][1] - e[0][1]);
    }
    listed_by[tid] = listed;
  }
  bool listed = true;
  for (std::size_t r = 0; r < rows; ++r) {
    listed = listed && listed_by[r];
    for (std::size_t t = 0; t < n_tiles; ++t) first[t + 1] += counts[r * n_tiles + t];
  }
  const std::vector<std::uint32_t> order = far_to_near(drops, std::move(key), listed);  // storage indices
  // The tiles' lists, far to near.
  for (std::size_t t = 0; t < n_tiles; ++t) first[t + 1] += first[t];
  bins.in_tile.resize(first[n_tiles]);
  {
    std::vector<std::size_t> fill(first.begin(), first.end() - 1);
    for (const std::uint32_t d : order) {
      const Span& sp = span[d];
      for (int ty = sp.ty0; ty <= sp.ty1; ++ty)
        for (int tx = sp.tx0; tx <= sp.tx1; ++tx) bins.in_tile[fill[static_cast<std::size_t>(ty) * tiles_x + tx]++] = d;
    }
  }
  // The mean length of the paths, summed far to near.
  double total_len = 0.0;
  for (const std::uint32_t d : order) total_len += path[d];
  bins.mean_streak_px = total_len / static_cast<double>(n);
  return bins;
}

// The streaks, composited far to near, tile by tile: a tile's pixels stay in cache while the
// streaks that can touch it (listed in their order: bin_streaks) are splatted, each pixel taking
// the same updates in the same order as a single pass over them would give it (the same image on
// any number of threads). A streak's rows and columns (v_lo..v_hi, u_lo..u_hi) bound every pixel
// its samples touch; its tiles are taken one pixel wider. A tile's loop fetches the streaks a few
// ahead of the one it draws.
StreakSplat splat_streaks(const StreakSlabs& slabs, ConstImageView range, Image& out, const StreakCamera& cam,
                          int nt) {
  constexpr int kTileW = 128, kTileH = 32;
  const StreakBins bins = bin_streaks(slabs, cam, kTileW, kTileH, nt);
  const std::vector<const Streak*>& drops = bins.drops;
  if (drops.empty()) return {};
  const int W = cam.width, H = cam.height;
  const double fx = cam.fx, fy = cam.fy, cx = cam.cx, cy = cam.cy;
  const int tiles_x = bins.tiles_x;
  const std::size_t n_tiles = static_cast<std::size_t>(tiles_x) * bins.tiles_y;
  const std::vector<std::size_t>& first = bins.first;
  const std::vector<std::uint32_t>& in_tile = bins.in_tile;
  // The tiles taken longest list first (a tile's pixels depend on its list alone: any order, the
  // same image), so that no thread is left with a long tile at the end.
  std::vector<int> by_work(n_tiles);
  for (std::size_t t = 0; t < n_tiles; ++t) by_work[t] = static_cast<int>(t);
  std::stable_sort(by_work.begin(), by_work.end(),
                   [&](int a, int b) { return first[a + 1] - first[a] > first[b + 1] - first[b]; });
  std::vector<std::size_t> clamped(static_cast<std::size_t>(nt), 0);
#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num();
    std::vector<double> wx, wy;
    // A streak's samples in the tile, a column each (their image position u, v, range r, coverage
    // a and 1/(depth softness)): the loops that fill them are vectorised.
    std::vector<double> sample_col[6];
    std::vector<float> depth(static_cast<std::size_t>(kTileW) * kTileH);
    float* const pixels = out.data.data();
#pragma omp for schedule(dynamic, 1)
    for (std::size_t w = 0; w < n_tiles; ++w) {
      const int tile = by_work[w];
      const int y_lo = tile / tiles_x * kTileH, y_hi = std::min(H, y_lo + kTileH);
      const int x_lo = tile % tiles_x * kTileW, x_hi = std::min(W, x_lo + kTileW);
      // The tile's ranges, an unknown one (the sky) as +inf: its depth test below gives 1, as
      // the test's visibility 1 there.
      for (int y = y_lo; y < y_hi; ++y)
        for (int x = x_lo; x < x_hi; ++x) {
          const float rs = range.at(x, y);
          depth[static_cast<std::size_t>(y - y_lo) * kTileW + (x - x_lo)] =
              streak_range_known(rs) ? rs : std::numeric_limits<float>::infinity();
        }
      std::size_t tile_clamped = 0;
      const std::size_t e0 = first[static_cast<std::size_t>(tile)], e1 = first[static_cast<std::size_t>(tile) + 1];
      for (std::size_t e = e0; e < e1; ++e) {
        if (e + kAhead < e1) {
          const char* next = reinterpret_cast<const char*>(drops[in_tile[e + kAhead]]);
          __builtin_prefetch(next);
          __builtin_prefetch(next + 64);
          __builtin_prefetch(next + sizeof(Streak) - 1);
        }
        const Streak& k = *drops[in_tile[e]];
        const StreakSampling smp = streak_sampling(k, cam);
        const double va = smp.va, vb = smp.vb;
        const int n = smp.n, rad = smp.rad;
        const bool gauss = smp.gauss;
        // The samples that can have a tap in the tile's rows: the image path is straight and its
        // row monotone in t, so they are a run of indices, found by bisection on rows a pixel
        // beyond any tap's reach (far above the rounding of v); the others are not computed.
        int i_lo = 0, i_hi = n;
        if (n > 8) {
          const double row_lo = y_lo - rad - 2.0, row_hi = y_hi + rad + 1.0;
          const auto row = [&](int i) {
            const double t = k.t0 + (k.t1 - k.t0) * (i + 0.5) / n;
            return fy * (k.c[1] + k.u[1] * t) / (k.c[2] + k.u[2] * t) + cy;
          };
          // The index where the exact path's row crosses R (t from v(t) = R, the projection
          // inverted), a guess: the first index where `holds` turns true is looked for about it,
          // a few steps each way, else by bisection. `holds` is monotone in i but for rounding
          // within far less than a pixel of R, where no sample has a tap in the tile: any index
          // there lists the same taps.
          const auto guess = [&](double R) {
            const double t = (fy * k.c[1] - (R - cy) * k.c[2]) / ((R - cy) * k.u[2] - fy * k.u[1]);
            return (t - k.t0) * n / (k.t1 - k.t0) - 0.5;
          };
          const auto first_true = [n](const auto& holds, double g) {  // the first index where `holds` turns true
            if (!std::isnan(g)) {
              int i = static_cast<int>(std::ceil(std::min(static_cast<double>(n), std::max(0.0, g))));
              for (int step = 0; step < 4; ++step) {
                if (i > 0 && holds(i - 1)) --i;
                else if (i < n && !holds(i)) ++i;
                else return i;
              }
            }
            int a = 0, b = n;
            while (a < b) {
              const int mid = a + (b - a) / 2;
              if (holds(mid)) b = mid;
              else a = mid + 1;
            }
            return a;
          };
          if (vb >= va) {
            i_lo = first_true([&](int i) { return row(i) >= row_lo; }, guess(row_lo));
            i_hi = first_true([&](int i) { return row(i) >= row_hi; }, guess(row_hi));
          } else {
            i_lo = first_true([&](int i) { return row(i) < row_hi; }, guess(row_hi));
            i_hi = first_true([&](int i) { return row(i) < row_lo; }, guess(row_lo));
          }
        }
        // The samples' positions and weights first (independent of one another: a column each,
        // the divisions two at a time in vector registers, the same quotients), then their taps in
        // order.
        const int m = std::max(0, i_hi - i_lo);
        if (sample_col[0].size() < static_cast<std::size_t>(m))
          for (std::vector<double>& c : sample_col) c.resize(static_cast<std::size_t>(m));
        double* __restrict su = sample_col[0].data();
        double* __restrict sv = sample_col[1].data();
        double* __restrict sr = sample_col[2].data();
        double* __restrict sa = sample_col[3].data();
        double* __restrict si = sample_col[4].data();
        double* __restrict sz = sample_col[5].data();
        {
          // (The streak's fields as locals: the stores below could alias them.)
          const double c0 = k.c[0], c1 = k.c[1], c2 = k.c[2], u0 = k.u[0], u1 = k.u[1], u2 = k.u[2];
          const double t0 = k.t0, dt = k.t1 - k.t0, area = k.area, nd = n;
          for (int j = 0; j < m; ++j) {
            const double t = t0 + dt * ((i_lo + j) + 0.5) / nd;
            const double x = c0 + u0 * t, y = c1 + u1 * t, z = c2 + u2 * t;
            su[j] = fx * x / z + cx, sv[j] = fy * y / z + cy;
            sr[j] = x * x + y * y + z * z;
            sz[j] = z * z * z;
          }
          for (int j = 0; j < m; ++j) sr[j] = std::sqrt(sr[j]);
          // The coverage over the exposure is the time average of the particle's image area there.
          for (int j = 0; j < m; ++j) {
            sa[j] = area * sr[j] / sz[j] / nd;
            si[j] = 1.0 / (kRainDepthSoftness * sr[j]);
          }
        }
        const float ke[3] = {k.e[0], k.e[1], k.e[2]};
        for (int j = 0; j < m; ++j) {
          const double u = su[j], v = sv[j], r = sr[j], a_sample = sa[j], inv_soft = si[j];
          const auto put = [&](int x, int y, double w) {
            if (x < x_lo || x >= x_hi || y < y_lo || y >= y_hi || !(w > 0.0)) return;
            const float rs = depth[static_cast<std::size_t>(y - y_lo) * kTileW + (x - x_lo)];
            const double vis = std::min(1.0, std::max(0.0, (rs - r) * inv_soft));
            double a = w * a_sample * vis;
            if (!(a > 0.0)) return;
            if (a > 1.0) a = 1.0, ++tile_clamped;
            float* o = pixels + (static_cast<std::size_t>(y) * W + x) * 3;
            for (int q = 0; q < 3; ++q) o[q] += static_cast<float>(a) * (ke[q] - o[q]);
          };
          if (!gauss) {
            const double fu = std::floor(u), fv = std::floor(v);
            const int x0 = static_cast<int>(fu), y0 = static_cast<int>(fv);
            if (x0 + 1 < x_lo || x0 >= x_hi || y0 + 1 < y_lo || y0 >= y_hi) continue;  // no tap in the tile
            const double ax = u - fu, ay = v - fv;
            put(x0, y0, (1 - ax) * (1 - ay));
            put(x0 + 1, y0, ax * (1 - ay));
            put(x0, y0 + 1, (1 - ax) * ay);
            put(x0 + 1, y0 + 1, ax * ay);
          } else {
            const int xc = static_cast<int>(std::lround(u)), yc = static_cast<int>(std::lround(v));
            if (yc + rad < y_lo || yc - rad >= y_hi || xc + rad < x_lo || xc - rad >= x_hi) continue;
            wx.assign(2 * rad + 1, 0.0), wy.assign(2 * rad + 1, 0.0);
            double sx = 0.0, sy = 0.0;
            const double inv = 1.0 / (2.0 * k.sigma_px * k.sigma_px);
            for (int j = -rad; j <= rad; ++j) {
              sx += wx[j + rad] = std::exp(-std::pow(xc + j - u, 2) * inv);
              sy += wy[j + rad] = std::exp(-std::pow(yc + j - v, 2) * inv);
            }
            for (int jy = -rad; jy <= rad; ++jy) {
              const int y = yc + jy;
              if (y < y_lo || y >= y_hi) continue;
              for (int jx = -rad; jx <= rad; ++jx) put(xc + jx, y, wx[jx + rad] * wy[jy + rad] / (sx * sy));
            }
          }
        }
      }
      clamped[static_cast<std::size_t>(tid)] += tile_clamped;
    }
  }
  StreakSplat done;
  for (std::size_t i = 0; i < clamped.size(); ++i) done.alpha_clamped += clamped[i];
  done.drawn = drops.size();
  done.mean_streak_px = bins.mean_streak_px;
  return done;
}

}  // namespace brume
