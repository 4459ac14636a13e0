// brume study — a minimal line-plot renderer for the study's figures (see plot.hpp).
//
// Each panel is drawn into an 8-bit BGR cv::Mat with OpenCV imgproc alone (antialiased lines and Hershey fonts), so
// no plotting dependency is needed: margins are sized from cv::getTextSize, series are clipped to the plot box with
// cv::clipLine and drawn into a view of the box, dashes are laid along the polyline in screen space, and the legend
// goes into the corner of the box that the curves cross least. The finished drawing is written byte for byte as an
// 8-bit sRGB PNG through brume::write_image.
#include "plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "brume/error.hpp"
#include "brume/io.hpp"
#include "brume_opencv.hpp"

namespace brume::plot {
namespace {

constexpr int kShift = 4;  // sub-pixel bits for cv::line and cv::circle
constexpr double kSub = 1 << kShift;

const cv::Scalar kInk(40, 40, 40);         // axes box and major ticks
const cv::Scalar kText(25, 25, 25);
const cv::Scalar kGrid(226, 226, 226);     // grid lines at major ticks
const cv::Scalar kMinor(150, 150, 150);    // minor ticks
const cv::Scalar kNote(95, 95, 95);
const cv::Scalar kLegendEdge(175, 175, 175);

// Fonts and spacings, scaled with the image width (960 px = 1).
struct Style {
  double f;
  int font = cv::FONT_HERSHEY_SIMPLEX;
  int title_font = cv::FONT_HERSHEY_DUPLEX;
  double title_scale, label_scale, tick_scale, legend_scale, note_scale;
  int thick;  // text stroke
  int pad, gap, tick, minor_tick;

  explicit Style(int width) : f(std::clamp(width / 960.0, 0.6, 3.0)) {
    title_scale = 0.66 * f;
    label_scale = 0.55 * f;
    tick_scale = 0.5 * f;
    legend_scale = 0.5 * f;
    note_scale = 0.45 * f;
    thick = std::max(1, static_cast<int>(std::lround(f)));
    pad = static_cast<int>(std::lround(12 * f));
    gap = static_cast<int>(std::lround(6 * f));
    tick = static_cast<int>(std::lround(6 * f));
    minor_tick = static_cast<int>(std::lround(3 * f));
  }
};

struct TextBox {
  int w = 0, h = 0, base = 0;  // width, height above the baseline, depth below it
};

TextBox measure(const std::string& s, int font, double scale, int thick) {
  if (s.empty()) return {};
  int base = 0;
  const cv::Size sz = cv::getTextSize(s, font, scale, thick, &base);
  return {sz.width, sz.height, base};
}

void put(cv::Mat& img, const std::string& s, cv::Point org, int font, double scale, const cv::Scalar& c, int thick) {
  cv::putText(img, s, org, font, scale, c, thick, cv::LINE_AA);
}

// Largest scale <= `scale` at which `s` fits in `avail` pixels (so that a long title never runs off the image).
double fit_scale(const std::string& s, int font, double scale, int thick, int avail) {
  while (scale > 0.25 && measure(s, font, scale, thick).w > avail) scale *= 0.92;
  return scale;
}

// A tick label: `base`, then `sup` as a superscript (10^-4 is {"10", "-4"}).
struct Label {
  std::string base, sup;
};

struct LabelMetrics {
  TextBox all;       // the whole label
  TextBox base;      // the base part alone
  double sup_scale;  // font scale of the superscript
  int raise;         // superscript baseline above the base's
};

LabelMetrics measure(const Label& l, const Style& st) {
  LabelMetrics m;
  m.base = measure(l.base, st.font, st.tick_scale, st.thick);
  m.sup_scale = 0.72 * st.tick_scale;
  m.raise = static_cast<int>(std::lround(0.62 * m.base.h));
  m.all = m.base;
  if (!l.sup.empty()) {
    const TextBox s = measure(l.sup, st.font, m.sup_scale, st.thick);
    m.all.w += 1 + s.w;
    m.all.h = std::max(m.base.h, m.raise + s.h);
  }
  return m;
}

void put(cv::Mat& img, const Label& l, const LabelMetrics& m, cv::Point org, const Style& st) {
  put(img, l.base, org, st.font, st.tick_scale, kText, st.thick);
  if (!l.sup.empty())
    put(img, l.sup, {org.x + m.base.w + 1, org.y - m.raise}, st.font, m.sup_scale, kText, st.thick);
}

// `s` drawn reading upwards, horizontally from x_left, centred on y_centre.
void put_vertical(cv::Mat& img, const std::string& s, int x_left, int y_centre, const Style& st) {
  const TextBox t = measure(s, st.font, st.label_scale, st.thick);
  cv::Mat tmp(t.h + t.base + 2, t.w + 2, CV_8UC3, cv::Scalar::all(255));
  put(tmp, s, {1, t.h + 1}, st.font, st.label_scale, kText, st.thick);
  cv::Mat rot;
  cv::rotate(tmp, rot, cv::ROTATE_90_COUNTERCLOCKWISE);
  const cv::Rect dst(x_left, y_centre - rot.rows / 2, rot.cols, rot.rows);
  const cv::Rect vis = dst & cv::Rect(0, 0, img.cols, img.rows);
  if (vis.empty()) return;
  cv::Mat out = img(vis);
  cv::min(out, rot(cv::Rect(vis.x - dst.x, vis.y - dst.y, vis.width, vis.height)), out);
}

// "%.3g" without the padding of the exponent: 2e-05 -> 2e-5, 1e+06 -> 1e6.
std::string compact(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  std::string s = buf;
  const auto e = s.find('e');
  if (e == std::string::npos) return s;
  std::string mant = s.substr(0, e), ex = s.substr(e + 1);
  const bool neg = !ex.empty() && ex[0] == '-';
  if (!ex.empty() && (ex[0] == '-' || ex[0] == '+')) ex.erase(0, 1);
  while (ex.size() > 1 && ex[0] == '0') ex.erase(0, 1);
  return mant + "e" + (neg ? "-" : "") + ex;
}

struct Axis {
  bool log = false;
  double lo = 0, hi = 1;              // range in data units (log: lo > 0)
  std::vector<double> major, minor;   // tick positions
  std::vector<double> label_at;       // labelled positions
  std::vector<Label> labels;

  bool valid(double v) const { return std::isfinite(v) && (!log || v > 0); }
  double frac(double v) const {       // 0 at lo, 1 at hi
    if (!log) return (v - lo) / (hi - lo);
    return (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo));
  }
};

// Room that labels need between neighbouring ticks, in pixels along the axis.
int needed_room(const std::vector<Label>& labels, bool horizontal, const Style& st) {
  int room = 0;
  for (const Label& l : labels) {
    const LabelMetrics m = measure(l, st);
    room = std::max(room, horizontal ? m.all.w + 2 * st.gap : 2 * (m.all.h + m.all.base));
  }
  return room;
}

// Linear axis: the smallest 1-2-5 x 10^k step that gives at most 8 ticks whose labels do not touch. Automatic ends
// are expanded to whole steps.
void linear_axis(Axis& a, double dmin, double dmax, bool auto_lo, bool auto_hi, double pixels, bool horizontal,
                 const Style& st) {
  const double span = dmax - dmin;
  const double base = std::pow(10.0, std::floor(std::log10(span)) - 2);
  for (int j = 0; j < 18; ++j) {
    const double step = base * std::pow(10.0, j / 3) * (j % 3 == 0 ? 1 : j % 3 == 1 ? 2 : 5);
    const double lo = auto_lo ? std::floor(dmin / step + 1e-9) * step : dmin;
    const double hi = auto_hi ? std::ceil(dmax / step - 1e-9) * step : dmax;
    const double first = std::ceil(lo / step - 1e-9), last = std::floor(hi / step + 1e-9);
    if (last - first + 1 > 8 && j < 17) continue;
    a.lo = lo, a.hi = hi;
    a.major.clear(), a.labels.clear();
    const int decimals = std::max(0, -static_cast<int>(std::floor(std::log10(step) + 1e-9)));
    const bool sci = std::max(std::abs(lo), std::abs(hi)) >= 1e6 || decimals > 5;
    for (double k = first; k <= last; ++k) {
      double v = k * step;
      if (std::abs(v) < step * 1e-9) v = 0;
      char buf[48];
      if (sci) {
        a.labels.push_back({compact(v), ""});
      } else {
        std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
        a.labels.push_back({buf, ""});
      }
      a.major.push_back(v);
    }
    a.label_at = a.major;
    const double step_px = step / (hi - lo) * pixels;
    if (step_px >= needed_room(a.labels, horizontal, st) || j == 17) return;
  }
}

// Log axis: majors at each decade (labelled 10^k, every k-th decade when crowded), minors at 2..9 when there is room.
void log_axis(Axis& a, double dmin, double dmax, bool auto_lo, bool auto_hi, double pixels, bool horizontal,
              const Style& st) {
  a.lo = auto_lo ? std::pow(10.0, std::floor(std::log10(dmin) + 1e-9)) : dmin;
  a.hi = auto_hi ? std::pow(10.0, std::ceil(std::log10(dmax) - 1e-9)) : dmax;
  if (a.hi <= a.lo) a.hi = a.lo * 10;
  const double l0 = std::log10(a.lo), l1 = std::log10(a.hi);
  const int e0 = static_cast<int>(std::ceil(l0 - 1e-9)), e1 = static_cast<int>(std::floor(l1 + 1e-9));
  const double decade_px = pixels / (l1 - l0);
  for (int e = e0; e <= e1; ++e) a.major.push_back(std::pow(10.0, e));
  if (decade_px >= 28 * st.f)
    for (int d = static_cast<int>(std::floor(l0 + 1e-9)); d <= e1; ++d)
      for (int m = 2; m <= 9; ++m) {
        const double v = m * std::pow(10.0, d);
        if (v >= a.lo * (1 - 1e-9) && v <= a.hi * (1 + 1e-9)) a.minor.push_back(v);
      }
  if (e1 - e0 + 1 >= 2) {
    const int room = needed_room({{"10", "-88"}}, horizontal, st);
    int every = 1;
    for (int k : {1, 2, 3, 5, 10, 20, 50, 100}) {
      every = k;
      if (k * decade_px >= room) break;
    }
    for (int e = e0; e <= e1; ++e)
      if (((e % every) + every) % every == 0) {
        a.label_at.push_back(std::pow(10.0, e));
        a.labels.push_back({"10", std::to_string(e)});
      }
    return;
  }
  // Less than two decades inside the range: label the decade (if any) and the 2s and 5s in plain numbers.
  std::vector<double> at = a.major;
  for (int d = static_cast<int>(std::floor(l0 + 1e-9)); d <= e1 + 1; ++d)
    for (int m : {2, 5}) {
      const double v = m * std::pow(10.0, d);
      if (v >= a.lo * (1 - 1e-9) && v <= a.hi * (1 + 1e-9)) at.push_back(v);
    }
  std::sort(at.begin(), at.end());
  for (double v : at) {
    a.label_at.push_back(v);
    a.labels.push_back({compact(v), ""});
  }
}

void make_axis(Axis& a, double dmin, double dmax, double umin, double umax, double pixels, bool horizontal,
               const Style& st) {
  a.major.clear(), a.minor.clear(), a.label_at.clear(), a.labels.clear();
  const bool auto_lo = !std::isfinite(umin), auto_hi = !std::isfinite(umax);
  double lo = auto_lo ? dmin : umin, hi = auto_hi ? dmax : umax;
  if (!(lo < hi)) {  // one point, or data on the wrong side of a fixed limit
    if (a.log) {
      if (auto_lo && auto_hi) lo /= 2, hi *= 2;
      else if (auto_lo) lo = hi / 10;
      else hi = lo * 10;
    } else {
      const double d = lo == 0 && hi == 0 ? 1 : std::max(std::abs(lo), std::abs(hi)) * 0.1;
      if (auto_lo && auto_hi) lo -= d, hi += d;
      else if (auto_lo) lo = hi - 10 * d;
      else hi = lo + 10 * d;
    }
  }
  if (a.log) log_axis(a, lo, hi, auto_lo, auto_hi, pixels, horizontal, st);
  else linear_axis(a, lo, hi, auto_lo, auto_hi, pixels, horizontal, st);
}

cv::Point fixed(cv::Point2d p) {
  return {static_cast<int>(std::lround(p.x * kSub)), static_cast<int>(std::lround(p.y * kSub))};
}

// Clips a-b (pixels) to the image of size `sz` with cv::clipLine; false when nothing is left.
bool clip(cv::Size sz, cv::Point2d& a, cv::Point2d& b) {
  auto to_l = [](cv::Point2d p) {  // far-off points are pulled in to keep clipLine's arithmetic in range
    const double lim = 1e8;
    return cv::Point2l(std::llround(std::clamp(p.x, -lim, lim) * kSub),
                       std::llround(std::clamp(p.y, -lim, lim) * kSub));
  };
  cv::Point2l p = to_l(a), q = to_l(b);
  const auto w = static_cast<std::int64_t>(sz.width - 1) * (1 << kShift) + 1;
  const auto h = static_cast<std::int64_t>(sz.height - 1) * (1 << kShift) + 1;
  if (!cv::clipLine(cv::Size2l(w, h), p, q)) return false;
  a = {p.x / kSub, p.y / kSub}, b = {q.x / kSub, q.y / kSub};
  return true;
}

struct Pen {
  cv::Scalar colour;
  int thickness = 2;
  bool dashed = false;
  double on = 0, off = 0;  // dash pattern, pixels
};

Pen make_pen(const Series& s, const Style& st) {
  Pen p;
  p.colour = cv::Scalar(s.b, s.g, s.r);
  p.thickness = std::max(1, static_cast<int>(std::lround(std::max(1, s.thickness) * st.f)));
  p.dashed = s.dashed;
  p.on = (7 + 2.5 * p.thickness) * st.f;
  p.off = (4 + 1.5 * p.thickness) * st.f;
  return p;
}

// A polyline of consecutive valid points, in pixels of `img`, clipped to it; dashes run on along the whole polyline.
void draw_polyline(cv::Mat& img, const std::vector<cv::Point2d>& pts, const Pen& pen) {
  double dist = 0;
  const double period = pen.on + pen.off;
  for (std::size_t i = 1; i < pts.size(); ++i) {
    const cv::Point2d a0 = pts[i - 1], b0 = pts[i];
    const double len = std::hypot(b0.x - a0.x, b0.y - a0.y);
    cv::Point2d a = a0, b = b0;
    if (len > 0 && clip(img.size(), a, b)) {
      if (!pen.dashed) {
        cv::line(img, fixed(a), fixed(b), pen.colour, pen.thickness, cv::LINE_AA, kShift);
      } else {
        const cv::Point2d dir = (b0 - a0) / len;
        double s = std::clamp((a - a0).dot(dir), 0.0, len);
        const double s1 = std::clamp((b - a0).dot(dir), 0.0, len);
        while (s < s1) {
          const double ph = std::fmod(dist + s, period);
          const bool on = ph < pen.on;
          const double next = s + (on ? pen.on - ph : period - ph);
          const double e = std::min(next, s1);
          if (on && e > s) cv::line(img, fixed(a0 + dir * s), fixed(a0 + dir * e), pen.colour, pen.thickness,
                                    cv::LINE_AA, kShift);
          s = next;
        }
      }
    }
    dist += len;
  }
}

void draw_marker(cv::Mat& img, cv::Point2d p, const Pen& pen, double radius) {
  if (p.x < -radius || p.y < -radius || p.x > img.cols + radius || p.y > img.rows + radius) return;
  cv::circle(img, fixed(p), static_cast<int>(std::lround(radius * kSub)), pen.colour, cv::FILLED, cv::LINE_AA, kShift);
}

double marker_radius(const Pen& pen, const Style& st) { return 1.4 * pen.thickness + 1.2 * st.f; }

// The legend's size: entries run down `cols` columns.
struct LegendLayout {
  std::vector<const Series*> entries;
  int sample = 0, row_h = 0, col_w = 0, text_h = 0;
  int cols = 1, rows = 0, w = 0, h = 0;

  LegendLayout(const Panel& p, const Style& st) {
    for (const Series& s : p.series)
      if (!s.label.empty()) entries.push_back(&s);
    int text_w = 0, text_base = 0;
    for (const Series* s : entries) {
      const TextBox t = measure(s->label, st.font, st.legend_scale, st.thick);
      text_w = std::max(text_w, t.w), text_h = std::max(text_h, t.h), text_base = std::max(text_base, t.base);
    }
    sample = static_cast<int>(std::lround(40 * st.f));
    row_h = text_h + text_base + st.gap;
    col_w = st.gap + sample + st.gap + text_w + st.gap;
    set_cols(1, st);
  }
  void set_cols(int c, const Style& st) {
    const int n = static_cast<int>(entries.size());
    cols = std::max(1, std::min(c, n));
    rows = (n + cols - 1) / cols;
    w = cols * col_w + st.gap / 2;
    h = st.gap + row_h * rows + st.gap / 2;
  }
  // Fewest columns (at most 3) that keep the height within `max_h` and the width within `max_w`.
  void fit(int max_h, int max_w, const Style& st) {
    for (int c = 1; c <= 3; ++c) {
      set_cols(c, st);
      if (h <= max_h) return;
      if ((c + 1) * col_w + st.gap / 2 > max_w) return;
    }
  }
};

void draw_legend(cv::Mat& img, const LegendLayout& lg, cv::Point at, bool translucent, const Style& st) {
  const cv::Rect r = cv::Rect(at.x, at.y, lg.w, lg.h) & cv::Rect(0, 0, img.cols, img.rows);
  if (r.empty()) return;
  if (translucent) {
    cv::Mat under = img(r);
    cv::addWeighted(under, 0.2, cv::Mat(under.size(), under.type(), cv::Scalar::all(255)), 0.8, 0, under);
  }
  cv::rectangle(img, r, kLegendEdge, 1);
  for (int i = 0; i < static_cast<int>(lg.entries.size()); ++i) {
    const Series& s = *lg.entries[i];
    const Pen pen = make_pen(s, st);
    const double cy = at.y + st.gap + lg.row_h * (i % lg.rows + 0.5);
    const double sx = at.x + st.gap + lg.col_w * (i / lg.rows);
    draw_polyline(img, {{sx, cy}, {sx + lg.sample, cy}}, pen);
    if (s.markers) draw_marker(img, {sx + lg.sample / 2.0, cy}, pen, marker_radius(pen, st));
    put(img, s.label, {static_cast<int>(sx) + lg.sample + st.gap, static_cast<int>(std::lround(cy)) + lg.text_h / 2},
        st.font, st.legend_scale, kText, st.thick);
  }
}

// Margins of a panel's plot box; stacked panels share the widest, so that their boxes line up.
struct Frame {
  int left = 0, right = 0;
  int reserve = 0;  // part of `right` kept for a legend outside the box
};

// Draws one panel with margins of at least `want`; returns the margins it used.
Frame draw_panel(cv::Mat& img, const Panel& p, const Style& st, const Frame& want) {
  const int W = img.cols, H = img.rows;
  Axis ax, ay;
  ax.log = p.log_x, ay.log = p.log_y;

  // Data extents and checks.
  double xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
  for (const Series& s : p.series) {
    if (s.x.size() != s.y.size())
      throw Error("plot: panel '" + p.title + "', series '" + s.label + "': " + std::to_string(s.x.size()) +
                  " x values but " + std::to_string(s.y.size()) + " y values; they must pair up");
    for (std::size_t i = 0; i < s.x.size(); ++i)
      if (ax.valid(s.x[i]) && ay.valid(s.y[i])) {
        xmin = std::min(xmin, s.x[i]), xmax = std::max(xmax, s.x[i]);
        ymin = std::min(ymin, s.y[i]), ymax = std::max(ymax, s.y[i]);
      }
  }
  auto check = [&](const char* name, double lo, double hi, bool log) {
    if (log && ((std::isfinite(lo) && lo <= 0) || (std::isfinite(hi) && hi <= 0)))
      throw Error(std::string("plot: panel '") + p.title + "': " + name + " limits must be positive on a log axis");
    if (std::isfinite(lo) && std::isfinite(hi) && !(lo < hi))
      throw Error(std::string("plot: panel '") + p.title + "': " + name + " limits need min < max");
  };
  check("x", p.xmin, p.xmax, p.log_x);
  check("y", p.ymin, p.ymax, p.log_y);
  const bool empty = !(xmin <= xmax);
  if (empty) {
    xmin = ax.log ? 1 : 0, xmax = ax.log ? 10 : 1;
    ymin = ay.log ? 1 : 0, ymax = ay.log ? 10 : 1;
  }

  // Vertical layout: title, note, plot box, tick labels, x label.
  const int avail = W - 2 * st.pad;
  const double title_scale = fit_scale(p.title, st.title_font, st.title_scale, st.thick, avail);
  const double note_scale = fit_scale(p.note, st.font, st.note_scale, st.thick, avail);
  const TextBox tb = measure(p.title, st.title_font, title_scale, st.thick);
  const TextBox nb = measure(p.note, st.font, note_scale, st.thick);
  const TextBox xl = measure(p.xlabel, st.font, st.label_scale, st.thick);
  const TextBox yl = measure(p.ylabel, st.font, st.label_scale, st.thick);
  const LabelMetrics tick_m = measure(Label{"10", "-8"}, st);
  const TextBox digits = measure("0123456789", st.font, st.tick_scale, st.thick);
  const int tick_h = std::max(tick_m.all.h, digits.h), tick_base = std::max(tick_m.all.base, digits.base);

  int y = st.pad;
  const int title_base = y + tb.h;
  if (!p.title.empty()) y = title_base + tb.base + st.gap;
  const int note_base = y + nb.h;
  if (!p.note.empty()) y = note_base + nb.base + st.gap;
  const int top = y + std::max(st.gap, tick_h / 2 + 2);
  const int bottom = st.tick + st.gap + tick_h + tick_base + (p.xlabel.empty() ? 0 : st.gap + xl.h + xl.base) + st.pad;
  const int plot_h = H - top - bottom;
  if (plot_h < 40)
    throw Error("plot: panel height " + std::to_string(H) + " leaves no room for the plot; use at least " +
                std::to_string(H - plot_h + 40));

  make_axis(ay, ymin, ymax, p.ymin, p.ymax, plot_h, false, st);
  int ytick_w = 0;
  for (const Label& l : ay.labels) ytick_w = std::max(ytick_w, measure(l, st).all.w);
  const int ylabel_w = p.ylabel.empty() ? 0 : yl.h + yl.base + 2 + st.gap;
  const int left = std::max(want.left, st.pad + ylabel_w + ytick_w + st.gap + st.tick);

  // Horizontal layout, with `reserve` pixels on the right kept for a legend outside the box.
  cv::Rect box;
  Frame used;
  auto layout = [&](int reserve) {
    int right = std::max(want.right, 2 * st.pad + reserve);
    for (int pass = 0; pass < 2; ++pass) {
      const int plot_w = W - left - right;
      if (plot_w < 60)
        throw Error("plot: width " + std::to_string(W) + " leaves no room for the plot of panel '" + p.title + "'");
      make_axis(ax, xmin, xmax, p.xmin, p.xmax, plot_w, true, st);
      box = cv::Rect(left, top, plot_w, plot_h);
      if (!ax.labels.empty() && ax.frac(ax.label_at.back()) > 0.999)
        right = std::max(right, measure(ax.labels.back(), st).all.w / 2 + st.pad);  // below any outside legend
    }
    used = {left, right, reserve};
  };
  auto X = [&](double v) { return box.x + ax.frac(v) * box.width; };
  auto Y = [&](double v) { return box.y + (1 - ay.frac(v)) * box.height; };
  // Runs of consecutive valid points of each series, in pixels relative to the box.
  auto screen_runs = [&](const Series& s) {
    std::vector<std::vector<cv::Point2d>> runs(1);
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (!ax.valid(s.x[i]) || !ay.valid(s.y[i])) {
        if (!runs.back().empty()) runs.emplace_back();
        continue;
      }
      runs.back().push_back({X(s.x[i]) - box.x, Y(s.y[i]) - box.y});
    }
    return runs;
  };

  // Legend: in the corner of the box that the curves cross least (upper left on ties), or outside the box on the
  // right when every corner would hide part of a curve or when a panel stacked with this one has put it there.
  LegendLayout lg(p, st);
  const int inset = st.gap + 2;
  cv::Point legend_at(-1, -1);
  bool legend_inside = true;
  layout(want.reserve);
  if (!lg.entries.empty()) {
    lg.fit(static_cast<int>(0.55 * box.height), box.width - 2 * inset, st);
    std::vector<cv::Point2d> occupied;  // samples every few pixels along the curves
    for (const Series& s : p.series)
      for (const auto& run : screen_runs(s))
        for (std::size_t i = 0; i < run.size(); ++i) {
          occupied.push_back(run[i]);
          if (i + 1 < run.size()) {
            const int n = static_cast<int>(std::min(2000.0, cv::norm(run[i + 1] - run[i]) / 3));
            for (int k = 1; k < n; ++k) occupied.push_back(run[i] + (run[i + 1] - run[i]) * (double(k) / n));
          }
        }
    const cv::Point corners[4] = {{inset, inset},
                                  {box.width - inset - lg.w, inset},
                                  {inset, box.height - inset - lg.h},
                                  {box.width - inset - lg.w, box.height - inset - lg.h}};
    std::size_t best_count = std::numeric_limits<std::size_t>::max();
    for (const cv::Point& c : corners) {
      const cv::Rect r(c.x - 3, c.y - 3, lg.w + 6, lg.h + 6);
      std::size_t n = 0;
      for (const cv::Point2d& q : occupied) n += r.contains(cv::Point(static_cast<int>(q.x), static_cast<int>(q.y)));
      if (n < best_count) best_count = n, legend_at = c + box.tl();
    }
    LegendLayout out = lg;
    out.fit(plot_h, W / 2, st);
    const int need = out.w + 2 * st.gap;
    if ((best_count > 0 || want.reserve >= need) && W - left - need - 2 * st.pad >= W / 2) {  // half the width stays
      lg = out, legend_inside = false;
      if (need > want.reserve) layout(need);
      legend_at = {box.x + box.width + 2 * st.gap, box.y};
    }
  }
  const int x1 = box.x + box.width, y1 = box.y + box.height;

  // Grid at the major ticks.
  for (double v : ax.major) {
    const int px = static_cast<int>(std::lround(X(v)));
    if (px > box.x && px < x1) cv::line(img, {px, box.y + 1}, {px, y1 - 1}, kGrid, 1);
  }
  for (double v : ay.major) {
    const int py = static_cast<int>(std::lround(Y(v)));
    if (py > box.y && py < y1) cv::line(img, {box.x + 1, py}, {x1 - 1, py}, kGrid, 1);
  }

  // Series: lines drawn into a view of the box so that nothing leaves it; markers of the points inside the box drawn
  // whole, even where they overhang its edge.
  cv::Mat area = img(cv::Rect(box.x, box.y, box.width + 1, box.height + 1));
  for (const Series& s : p.series) {
    const Pen pen = make_pen(s, st);
    for (const auto& run : screen_runs(s)) {
      draw_polyline(area, run, pen);
      if (!s.markers && run.size() != 1) continue;
      for (const cv::Point2d& q : run)
        if (q.x > -0.5 && q.y > -0.5 && q.x < box.width + 0.5 && q.y < box.height + 0.5)
          draw_marker(img, q + cv::Point2d(box.x, box.y), pen, marker_radius(pen, st));
    }
  }

  // Box, ticks and tick labels.
  cv::rectangle(img, {box.x, box.y}, {x1, y1}, kInk, 1);
  for (double v : ax.minor) {
    const int px = static_cast<int>(std::lround(X(v)));
    cv::line(img, {px, y1}, {px, y1 + st.minor_tick}, kMinor, 1);
  }
  for (double v : ay.minor) {
    const int py = static_cast<int>(std::lround(Y(v)));
    cv::line(img, {box.x - st.minor_tick, py}, {box.x, py}, kMinor, 1);
  }
  for (double v : ax.major) {
    const int px = static_cast<int>(std::lround(X(v)));
    cv::line(img, {px, y1}, {px, y1 + st.tick}, kInk, 1);
  }
  for (double v : ay.major) {
    const int py = static_cast<int>(std::lround(Y(v)));
    cv::line(img, {box.x - st.tick, py}, {box.x, py}, kInk, 1);
  }
  const int xtick_base = y1 + st.tick + st.gap + tick_h;
  for (std::size_t i = 0; i < ax.labels.size(); ++i) {
    const LabelMetrics m = measure(ax.labels[i], st);
    const int px = static_cast<int>(std::lround(X(ax.label_at[i])));
    put(img, ax.labels[i], m, {px - m.all.w / 2, xtick_base}, st);
  }
  for (std::size_t i = 0; i < ay.labels.size(); ++i) {
    const LabelMetrics m = measure(ay.labels[i], st);
    const int py = static_cast<int>(std::lround(Y(ay.label_at[i])));
    put(img, ay.labels[i], m, {box.x - st.tick - st.gap - m.all.w, py + m.base.h / 2}, st);
  }

  // Axis labels, title, note.
  if (!p.xlabel.empty())
    put(img, p.xlabel, {box.x + (box.width - xl.w) / 2, xtick_base + tick_base + st.gap + xl.h}, st.font,
        st.label_scale, kText, st.thick);
  if (!p.ylabel.empty()) put_vertical(img, p.ylabel, st.pad, box.y + box.height / 2, st);
  auto centred = [&](int w) {  // over the box, kept inside the image
    return std::clamp(box.x + (box.width - w) / 2, st.pad, std::max(st.pad, W - st.pad - w));
  };
  if (!p.title.empty()) put(img, p.title, {centred(tb.w), title_base}, st.title_font, title_scale, kText, st.thick);
  if (!p.note.empty()) put(img, p.note, {centred(nb.w), note_base}, st.font, note_scale, kNote, st.thick);
  if (empty) {
    const TextBox t = measure("no data", st.font, st.label_scale, st.thick);
    put(img, "no data", {box.x + (box.width - t.w) / 2, box.y + (box.height + t.h) / 2}, st.font, st.label_scale,
        kNote, st.thick);
  }
  if (!lg.entries.empty()) draw_legend(img, lg, legend_at, legend_inside, st);
  return used;
}

}  // namespace

Image render(const std::vector<Panel>& panels, int width, int panel_height) {
  if (panels.empty()) throw Error("plot: nothing to draw (no panels)");
  if (width < 240 || panel_height < 160)
    throw Error("plot: " + std::to_string(width) + "x" + std::to_string(panel_height) +
                " is too small for a panel; use at least 240x160");
  const Style st(width);
  cv::Mat canvas(panel_height * static_cast<int>(panels.size()), width, CV_8UC3);
  // Drawn twice: once to find each panel's margins, then again with the widest of them all.
  Frame want;
  for (int pass = 0; pass < 2; ++pass) {
    canvas.setTo(cv::Scalar::all(255));
    Frame widest = want;
    for (std::size_t i = 0; i < panels.size(); ++i) {
      cv::Mat view = canvas(cv::Rect(0, static_cast<int>(i) * panel_height, width, panel_height));
      const Frame f = draw_panel(view, panels[i], st, want);
      widest = {std::max(widest.left, f.left), std::max(widest.right, f.right), std::max(widest.reserve, f.reserve)};
    }
    if (panels.size() == 1) break;
    want = widest;
  }
  return from_canvas(canvas);
}

Image from_canvas(const cv::Mat& bgr8) {
  // The drawing's bytes are sRGB-encoded colours; hand them over in linear light, as every brume Image holds (sRGB
  // encoding on write gives back exactly the same bytes).
  float lut[256];
  for (int v = 0; v < 256; ++v) lut[v] = srgb_to_linear(v / 255.0f);
  Image out(bgr8.cols, bgr8.rows, 3);
  for (int yy = 0; yy < bgr8.rows; ++yy) {
    const cv::Vec3b* row = bgr8.ptr<cv::Vec3b>(yy);
    for (int xx = 0; xx < bgr8.cols; ++xx)
      for (int c = 0; c < 3; ++c) out.at(xx, yy, c) = lut[row[xx][2 - c]];  // BGR -> RGB
  }
  return out;
}

WriteOptions png_options() {
  WriteOptions opts;
  opts.bits = "8";
  opts.transfer = Transfer::srgb;
  opts.is_color = true;
  return opts;
}

void write_png(OutputSet& outs, const std::string& path, const std::vector<Panel>& panels, int width,
               int panel_height) {
  outs.write(path, render(panels, width, panel_height), png_options(), "--out-dir");
}

}  // namespace brume::plot
