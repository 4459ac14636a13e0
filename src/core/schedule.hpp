// brume — the OpenMP schedule of the per-row and per-pixel loops.
//
// Rows (and flat runs of pixels) are handed out a chunk at a time
// (`schedule(dynamic, kRowChunk)`), not split into one static share per
// thread: on a host shared with other processes a thread that loses its core
// then holds the others up by one chunk, not by its whole share (half the
// frame on two threads), and on an idle host a chunk costs one atomic
// increment (16 rows: 70 chunks for 1120 rows; aerial's rows were the first,
// src/effects/aerial/aerial.cpp). A chunk's arithmetic is the same whichever
// thread runs it, so no output depends on the schedule; loops that reduce
// with an order-dependent sum keep a fixed partition (their partial sums in
// blocks, summed in order: depth/prepare.cpp's solver).
#pragma once

namespace brume {

constexpr int kRowChunk = 16;        // rows a chunk
constexpr long kPixelChunk = 16384;  // pixels a chunk (16 rows of 1024)

}  // namespace brume
