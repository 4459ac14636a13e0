// brume — the composition of media for a scan and an image (brume/medium.hpp
// states the rules; docs/architecture.md, "The media layer").
#include "brume/medium.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "brume/error.hpp"
#include "core/text.hpp"
#include "media/scan_points_check.hpp"
#include "media/scan_returns.hpp"

namespace brume {

double Medium::optical_depth(const MediumRay&, double range_m) const {
  return extinction_per_m() * std::max(0.0, range_m - sampled_range_m());
}

void Medium::particles(const MediumRay&, double, double, std::vector<Particle>&) const {}

namespace {

// Point i's beam from the sensor's origin, and its range.
MediumRay beam_of(const float* q, double& range_m) {
  const double x = q[0], y = q[1], z = q[2];
  range_m = std::sqrt(x * x + y * y + z * z);
  const double k = range_m > 0.0 ? 1.0 / range_m : 0.0;
  return {{0.0, 0.0, 0.0}, {x * k, y * k, z * k}};
}

}  // namespace

void Medium::scan_optical_depths(const float* points, std::size_t n, double* tau) const {
  for (std::size_t i = 0; i < n; ++i) {
    double r = 0.0;
    const MediumRay b = beam_of(points + 4 * i, r);
    tau[i] = optical_depth(b, r);
  }
}

void Medium::scan_echoes(const float* points, std::size_t n, std::vector<ScanEcho>& out) const {
  std::vector<Particle> met;
  for (std::size_t i = 0; i < n; ++i) {
    double r = 0.0;
    const MediumRay b = beam_of(points + 4 * i, r);
    met.clear();
    particles(b, r, points[4 * i + 3], met);
    for (const Particle& p : met)
      if (p.range_m > 0.0 && p.range_m < r) out.push_back({i, p.range_m, p.echo});
  }
}

void check_scan_points(const float* points, std::size_t n, const std::string& what) {
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = points + 4 * i;
    if (!(std::isfinite(q[0]) && std::isfinite(q[1]) && std::isfinite(q[2]) && std::isfinite(q[3])))
      throw Error(what + ": point " + std::to_string(i) + " has a non-finite coordinate or intensity");
    if (q[3] < 0.0f)
      throw Error(what + ": point " + std::to_string(i) + " has a negative intensity " + text::g(q[3]) +
                  "; intensities are reflectances >= 0");
  }
}

bool Medium::scan_alone(const float*, float*, std::size_t, const std::string&) const { return false; }

ScanRun scan_through_media(const std::vector<const Medium*>& media, const float* in, float* out, std::size_t n,
                           const std::string& what, const ScanDetection* detection, std::uint8_t* labels) {
  return scan_through_media(media, in, out, n, what, detection, labels, ScanReturn::strongest);
}

ScanRun scan_through_media(const std::vector<const Medium*>& media, const float* in, float* out, std::size_t n,
                           const std::string& what, const ScanDetection* detection, std::uint8_t* labels,
                           ScanReturn mode) {
  const bool last = mode == ScanReturn::last;
  ScanRun run;
  run.points = n;
  if (!detection && media.size() == 1 && media[0]->scan_alone(in, out, n, what)) {
    // Its own model counts its own returns: a moved point is one that changed place.
    for (std::size_t i = 0; i < n; ++i) {
      const bool moved = std::memcmp(in + 4 * i, out + 4 * i, 3 * sizeof(float)) != 0;
      run.echoes += moved;
      if (labels) labels[i] = static_cast<std::uint8_t>(moved ? ScanLabel::moved : ScanLabel::kept);
    }
    return run;
  }
  const double floor = detection ? detection->floor_per_m2 : 0.0;
  // Extinctions add along every beam.
  std::vector<double> tau(n, 0.0), own(n);
  for (const Medium* m : media) {
    m->scan_optical_depths(in, n, own.data());
    for (std::size_t i = 0; i < n; ++i) tau[i] += own[i];
  }
  // The union of the media's echoes, each attenuated by the other media to its range.
  std::vector<double> best(n, -1.0), best_range(n, 0.0), best_reported(n, 0.0);
  std::vector<ScanEcho> echoes;
  for (std::size_t m = 0; m < media.size(); ++m) {
    echoes.clear();
    media[m]->scan_echoes(in, n, echoes);
    for (const ScanEcho& e : echoes) {
      double r0 = 0.0;
      const MediumRay b = beam_of(in + 4 * e.point, r0);
      double others = 0.0;
      for (std::size_t k = 0; k < media.size(); ++k)
        if (k != m) others += media[k]->optical_depth(b, e.range_m);
      const double t = std::exp(-2.0 * others);
      const double v = e.intensity * t;
      if (!std::isfinite(v))
        throw Error(what + ": point " + std::to_string(e.point) + " gets an echo of intensity " + text::g(v) +
                    " from a medium; an echo must be finite");
      if (detection && v < floor * r0 * r0) continue;  // below the floor: never detected
      if (last ? best[e.point] < 0.0 || e.range_m > best_range[e.point] : v > best[e.point])
        best[e.point] = v, best_range[e.point] = e.range_m,
        best_reported[e.point] = std::isnan(e.reported) ? v : e.reported * t;
    }
  }
  std::size_t k = 0;  // the next output slot (in input order; k <= i, so in place is safe)
  for (std::size_t i = 0; i < n; ++i) {
    const float* q = in + 4 * i;
    double r0 = 0.0;
    beam_of(q, r0);
    const double trans = std::exp(-2.0 * tau[i]);
    const double hard = q[3] * trans;
    // The target's clear power on its own scale: at least the floor where it was detected.
    const double clear = detection ? std::max<double>(q[3], floor * r0 * r0) : q[3];
    ScanLabel label = ScanLabel::kept;
    if (!last && best[i] > clear * trans && r0 > 0.0) {  // ties: the target
      label = ScanLabel::moved;
    } else if (detection && trans < 1.0 && clear > 0.0) {
      const double keep = std::exp(-(floor * r0 * r0 / clear) * (1.0 / trans - 1.0));
      const double u = hash_unit(hash_fold(hash_fold(detection->seed, 0x5ca7ull), i));
      if (!(u < keep)) label = best[i] >= 0.0 && r0 > 0.0 ? ScanLabel::moved : ScanLabel::lost;
    }
    if (labels) labels[i] = static_cast<std::uint8_t>(label);
    if (label == ScanLabel::lost) {
      ++run.lost;
      continue;
    }
    float* o = out + 4 * k++;
    if (label == ScanLabel::moved) {
      const double s = best_range[i] / r0;
      o[0] = static_cast<float>(q[0] * s), o[1] = static_cast<float>(q[1] * s), o[2] = static_cast<float>(q[2] * s);
      o[3] = static_cast<float>(best_reported[i]);
      ++run.echoes;
    } else {
      o[0] = q[0], o[1] = q[1], o[2] = q[2], o[3] = static_cast<float>(hard);
    }
  }
  return run;
}

const float* scan_points(const ConstImageView& v, const std::string& what, std::vector<float>& buffer) {
  if (v.width() != 4 || v.channels() != 1)
    throw Error(what + " must be an (N, 4) array of x, y, z, intensity; got " + std::to_string(v.height()) + " x " +
                std::to_string(v.width()) + (v.channels() > 1 ? " x " + std::to_string(v.channels()) : std::string()));
  if (v.contiguous()) return v.data();
  const std::size_t n = static_cast<std::size_t>(v.height());  // a strided array: gathered once
  buffer.resize(n * 4);
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 4; ++c) buffer[4 * i + c] = v.at(c, static_cast<int>(i), 0);
  return buffer.data();
}

Image image_through_media(const std::vector<const Medium*>& media, DenseImageRef rgb, DenseImageRef range,
                          const Camera& camera, const std::array<float, 3>& airlight) {
  if (rgb.channels != 3 || range.channels != 1 || rgb.width != camera.width || rgb.height != camera.height ||
      range.width != rgb.width || range.height != rgb.height)
    throw Error("image_through_media: an RGB image and a 1-channel range of the camera's size " +
                std::to_string(camera.width) + "x" + std::to_string(camera.height) + " are needed");
  Image out(rgb.width, rgb.height, 3);
  const Vec3 origin = camera.world_from_camera().translation;
  std::vector<Particle> met;
  for (int y = 0; y < rgb.height; ++y)
    for (int x = 0; x < rgb.width; ++x) {
      double c[3] = {rgb.at(x, y, 0), rgb.at(x, y, 1), rgb.at(x, y, 2)};
      const double l = range.at(x, y);
      if (std::isfinite(l) && l > 0.0) {
        const MediumRay ray{origin, camera.world_ray(x, y)};
        const auto tau = [&](double r) {
          double t = 0.0;
          for (const Medium* m : media) t += m->optical_depth(ray, r);
          return t;
        };
        met.clear();
        for (const Medium* m : media) m->particles(ray, l, 0.0, met);
        met.erase(std::remove_if(met.begin(), met.end(),
                                 [l](const Particle& p) { return !(p.range_m > 0 && p.range_m < l); }),
                  met.end());
        std::sort(met.begin(), met.end(), [](const Particle& a, const Particle& b) { return a.range_m > b.range_m; });
        // From the scene towards the camera: the segment behind each particle, then the particle.
        double tau_far = tau(l);
        const auto segment = [&](double near) {
          const double tau_near = tau(near);
          const double t = std::exp(-(tau_far - tau_near));
          for (int k = 0; k < 3; ++k) c[k] = t * c[k] + (1.0 - t) * airlight[k];
          tau_far = tau_near;
        };
        for (const Particle& p : met) {
          segment(p.range_m);
          const double a = p.coverage;
          if (!(a >= 0.0 && a <= 1.0))
            throw Error("image_through_media: a particle at " + text::g(p.range_m) + " m on pixel (" +
                        std::to_string(x) + ", " + std::to_string(y) + ") covers " + text::g(a) +
                        " of it; a medium's particle covers a fraction in [0, 1]");
          for (int k = 0; k < 3; ++k) c[k] = (1.0 - a) * c[k] + a * p.radiance[k];
        }
        segment(0.0);
      }
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = static_cast<float>(c[k]);
    }
  return out;
}

}  // namespace brume
