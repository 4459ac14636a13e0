// The peer of a whole `brume blur` run (issue #16, bench/bench_whole_run.py):
// one process that reads an RGB PFM, blurs it with OpenCV's GaussianBlur at
// sigma (cv::Size(0, 0): 2 * round(4 sigma) + 1 taps, reflected borders, as
// brume_bench_blur's peer) and writes an RGB PFM. It is what
//   python3 -c "import cv2; cv2.imwrite('o.pfm', cv2.GaussianBlur(cv2.imread('i.pfm', -1), (0, 0), 25))"
// does, less the interpreter's start-up and cv2's import (python3-opencv is
// not among brume's dependencies): a stricter peer than the script. The PFM
// is read and written with one fread/fwrite per row, no library: the least a
// one-shot process can spend on I/O. Links only opencv_core and
// opencv_imgproc, as brume does.
//
//   brume_oneshot_gaussian IN.pfm SIGMA OUT.pfm
#include <cstdio>
#include <cstdlib>
#include <string>

#include "brume_opencv.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s IN.pfm SIGMA OUT.pfm\n", argv[0]);
    return 2;
  }
  FILE* in = std::fopen(argv[1], "rb");
  if (!in) {
    std::perror(argv[1]);
    return 1;
  }
  char magic[3] = {};
  int w = 0, h = 0;
  double scale = 0;
  if (std::fscanf(in, "%2s %d %d %lf", magic, &w, &h, &scale) != 4 || std::string(magic) != "PF" || w <= 0 ||
      h <= 0 || scale >= 0) {
    std::fprintf(stderr, "%s: not a little-endian RGB PFM\n", argv[1]);
    return 1;
  }
  std::fgetc(in);  // the single whitespace after the scale
  cv::Mat src(h, w, CV_32FC3), dst;
  // PFM rows run bottom to top.
  for (int y = h - 1; y >= 0; --y)
    if (std::fread(src.ptr<float>(y), sizeof(float) * 3, static_cast<std::size_t>(w), in) != static_cast<std::size_t>(w)) {
      std::fprintf(stderr, "%s: short read\n", argv[1]);
      return 1;
    }
  std::fclose(in);
  const double sigma = std::atof(argv[2]);
  cv::GaussianBlur(src, dst, cv::Size(0, 0), sigma, sigma, cv::BORDER_REFLECT);
  FILE* out = std::fopen(argv[3], "wb");
  if (!out) {
    std::perror(argv[3]);
    return 1;
  }
  std::fprintf(out, "PF\n%d %d\n-1\n", w, h);
  for (int y = h - 1; y >= 0; --y) std::fwrite(dst.ptr<float>(y), sizeof(float) * 3, static_cast<std::size_t>(w), out);
  return std::fclose(out) == 0 ? 0 : 1;
}
