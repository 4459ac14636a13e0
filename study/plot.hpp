// brume study — a minimal line-plot renderer, left for the sky fit's scatter
// (sky_plot.cpp, drawn by `brume sky fit`); the diffusion study's figures are
// matplotlib's (python/brume/plots.py).
//
// Draws log- or linear-axis line plots (a few series per panel, panels stacked
// vertically, in the manner of Hansard's Figs. 6-7) with OpenCV imgproc only,
// so that the command line needs no plotting dependency, and writes them as
// 8-bit PNG through brume's own image I/O.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "brume/image.hpp"
#include "brume/io.hpp"
#include "brume_opencv.hpp"

namespace brume::plot {

struct Series {
  std::string label;              // legend entry; empty: not in the legend
  unsigned char r = 0, g = 0, b = 0;  // line colour
  std::vector<double> x, y;       // same length; points with non-finite or (on log axes) non-positive values are
                                  // skipped, breaking the line
  bool dashed = false;            // dashed line (e.g. GPU backend)
  bool markers = true;            // small filled circle at each point
  int thickness = 2;
};

struct Panel {
  std::string title;              // drawn above the plot area
  std::string xlabel, ylabel;
  bool log_x = false, log_y = true;
  double xmin = NAN, xmax = NAN, ymin = NAN, ymax = NAN;  // NAN = automatic from the data (log axes: whole decades,
                                                          // linear axes: whole tick steps)
  std::vector<Series> series;
  std::string note;               // optional one-line note drawn small under the title
};

// Panels stacked vertically, each `width` x `panel_height` pixels, white
// background; returns linear-light float RGB, like every brume Image (the 8-bit
// sRGB drawing decoded, so that sRGB encoding on write restores it exactly).
// Throws brume::Error on bad sizes, series whose x and y differ in length or
// explicit axis limits that cannot be used (lo >= hi, non-positive on a log axis).
Image render(const std::vector<Panel>& panels, int width = 960, int panel_height = 440);

// How the figures are stored: 8-bit PNG tagged sRGB (the drawn bytes come
// back exactly; a "linear" PNG would carry gAMA 1.0 and look washed out).
WriteOptions png_options();

// render + queue as an 8-bit sRGB PNG in `outs` (renamed into place by its
// commit()); throws brume::Error on failure.
void write_png(OutputSet& outs, const std::string& path, const std::vector<Panel>& panels, int width = 960,
               int panel_height = 440);

// An 8-bit BGR OpenCV drawing (CV_8UC3, sRGB-encoded bytes) as linear float
// RGB, the form render() returns and png_options() stores unchanged.
Image from_canvas(const cv::Mat& bgr8);

}  // namespace brume::plot
