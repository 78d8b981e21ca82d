#pragma once
// Finds where a row of the left image runs through a pattern that repeats along the row
// (a chessboard's squares, tiles, a fence, stripes): there a pixel matches about as well
// one period off, and only the pattern's ends tell the periods apart. census_sgm.cpp then
// keeps P2 at its full height across the pattern's edges, so that the paths carry what
// its ends say into it (CensusSgmSettings::periodic_patterns); everywhere else P2 stays
// lowered at intensity edges (likely depth edges), which keeps natural scenes' depth
// edges sharp.
//
// A row's strong edges (a step of at least kPeriodicEdgeStep grey levels over two pixels,
// at its steepest) of one polarity that follow each other at regular spacings, at least
// kPeriodicMinEdges of them with each spacing within kPeriodicSpacingTolerance percent of
// the one before, mark a pattern: from one period before the first to one period after the
// last, as long as the period is one the disparity range could confuse. The mark then
// spreads kPeriodicRowReach rows up and down, so that the rows between two that found the
// pattern (where a tilted pattern's edges meet at its corners, and a row sees too few)
// are in it too.
//
// The constants were measured on the real rig's chessboard and the 17 natural scenes of
// shared/data (docs/configuration.md, the `patterns` tuning): a pattern is a strong one
// (weaker edges mark more of the natural scenes' texture: at 60 grey levels, 68.5 % of the
// board and mean bad-2 4.96 %, against 68.2 % and 4.54 % at 80); runs of 4 edges find 10
// points less of the board.
//
// Reentrant: the functions keep no state; callers give each thread its own rows.

#include <cstddef>
#include <cstdint>

namespace stereod::sgm {

inline constexpr int kPeriodicEdgeStep = 80;         // grey levels over two pixels
inline constexpr int kPeriodicMinEdges = 3;          // edges of one polarity in a run
inline constexpr int kPeriodicSpacingTolerance = 35; // percent of the previous spacing
inline constexpr int kPeriodicRowReach = 5;          // rows a mark spreads up and down

// Rows y0..y1-1 of `raw` (width values a row, row-major): 1 where the row runs through a
// repeating pattern whose period lies within min_period..max_period pixels, else 0.
// scratch: at least 2 * width ints.
void markPeriodicRows(const uint8_t* image, size_t stride, int width, int y0, int y1,
                      int min_period, int max_period, int* scratch, uint8_t* raw);

// Rows y0..y1-1 of `mask`: 1 where `raw` is 1 in this row or one within kPeriodicRowReach
// rows of it (every row of `raw`, 0..height-1, may be read).
void spreadPeriodicRows(const uint8_t* raw, int width, int height, int y0, int y1, uint8_t* mask);

} // namespace stereod::sgm
