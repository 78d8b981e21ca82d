#pragma once
// The near-field probe: evidence that a surface nearer than the disparity range a matcher
// searched fills part of a region, whatever the matcher made of that surface.
//
// A surface nearer than the range has its true match beyond the range's near end. What
// the matcher reports there depends on the surface: a textured one matches nothing and is
// dropped, a uniform one takes the disparity of what surrounds it, a periodic one (tiles,
// a chessboard) matches one period off, as plausibly as the truth, at a disparity that
// lies inside the range and reads far too far. None of it says "nearer than the range" by
// itself. The probe looks past the range instead: it cuts the region into tiles, sums the
// census costs of a tile's textured pixels into one curve over every disparity its pixels
// can have (in the range and beyond it, up to the left edge of the right image), and
// calls a tile near evidence when
//  - the best sum beyond the range is clearly below the best within it (margin_percent):
//    the tile matches better nearer than the range can see; a periodic pattern whose
//    aliases tie inside the range does not pass, but its edges and the irregularities that
//    only the true match aligns do; and
//  - a neighbouring tile (4-neighbourhood) that passed too has its best beyond-range
//    disparity within agree_px of this one's: one surface, not chance. The minimum over
//    the hundreds of disparities beyond a short range is lower than the minimum over the
//    few inside it by chance alone on textured natural scenes; chance does not repeat in
//    the next tile at the same disparity.
// Measured on the real rig's chessboard (opencv-doc's 13 pairs) and the 17 scenes of the
// shared data: boards nearer than the range mark 35-47 % of the region, a board inside
// the range none, natural scenes searched over their whole range at most 1 % of a region.
//
// The core depends on the standard library and Highway only (no OpenCV), like the
// matcher. Thread-bound: one probe per caller; run() allocates nothing.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "pipeline/sgm/band_pool.hpp"
#include "pipeline/sgm/census_sgm.hpp"

namespace stereod::sgm {

// A rectangle of an image, in pixels.
struct PixelRect {
    int x = 0, y = 0, width = 0, height = 0;
};

// The part of `rect` inside a width x height image (empty where none is).
inline PixelRect clippedTo(PixelRect rect, int width, int height)
{
    const int x0 = std::clamp(rect.x, 0, width), y0 = std::clamp(rect.y, 0, height);
    const int x1 = std::clamp(rect.x + rect.width, x0, width);
    const int y1 = std::clamp(rect.y + rect.height, y0, height);
    return {x0, y0, x1 - x0, y1 - y0};
}

struct NearFieldProbeSettings {
    int tile_px = 8;            // tile side, pixels of the probed image
    int samples_per_tile = 16;  // at most this many textured pixels of a tile are summed
    int min_textured = 16;      // fewer textured pixels in a tile: no evidence from it
    int texture_min_range = 20; // grey levels over a pixel's 5x3 neighbourhood: textured
    int margin_percent = 20;    // beyond-range best this far below the in-range best
    // ... and a good match: at most this share of the census bits differ on average (a
    // tile that matches nothing well anywhere, an occlusion, gives no evidence).
    int good_match_percent = 20;
    // The samples' censuses differ by this share of their bits on average: a tile that
    // one straight edge crosses gives no evidence.
    int diversity_percent = 20;
    int agree_px = 2; // neighbouring tiles' beyond-range disparities agree
    // Disparities beyond the range are probed up to the range's near end plus this many
    // times the range's span (and never past the left edge of the right image).
    int beyond_spans = 2;
};

class NearFieldProbe {
  public:
    // For images of width x height pixels, probed by up to `threads` threads at once;
    // allocates its scratch (one set per thread).
    NearFieldProbe(int width, int height, const NearFieldProbeSettings& settings = {},
                   int threads = 1);

    // Probes the tiles of `region` (clipped to the image) against the census images of
    // the matcher's last compute() (`census`, whose image is `left`, rows `stride` bytes
    // apart), the matcher having searched disparities first..last. Afterwards
    // evidenceTiles() lists the tiles that are near evidence. With a pool, rows of tiles
    // are shared out over min(threads, its threads) bands; the result is the same.
    void run(const uint8_t* left, size_t stride, const CensusSgm& census, PixelRect region,
             int first, int last, BandPool* pool = nullptr);

    // The tiles of the last run() that are near evidence, in pixels of the probed image.
    const std::vector<PixelRect>& evidenceTiles() const { return evidence_; }
    // The tiles of the last run() that had texture enough to be probed.
    int probedTiles() const { return probed_; }

  private:
    struct Tile {
        bool passed = false; // beyond-range best clearly below the in-range best
        int beyond_disparity = 0;
    };

    // What one thread works in.
    struct Scratch {
        std::vector<uint16_t> curve;
        std::vector<int> sample_x, sample_y;
        std::vector<uint64_t> sample_census; // diverse()'s, per sample it takes
        int probed = 0;
    };
    // The part of the region run() probes, and what every tile of it shares.
    struct Grid {
        int x_begin, y_begin, x_end, y_end, tiles_x, tiles_y, first, last, beyond_last, bits;
    };

    static bool informative(const CensusRows& rows, int x, int bits);
    bool diverse(const CensusSgm& census, Scratch& scratch, int step) const;
    // Judges the tiles of tile rows ty0, ty0 + ty_step, ... (Tile::passed), with its own
    // scratch.
    void probeTileRows(const uint8_t* left, size_t stride, const CensusSgm& census,
                       const Grid& grid, int ty0, int ty_step, Scratch& scratch);

    int width_, height_;
    NearFieldProbeSettings settings_;
    std::vector<Tile> tiles_; // the region's tile grid, row-major
    std::vector<Scratch> scratch_;
    std::vector<PixelRect> evidence_;
    int probed_ = 0;
};

} // namespace stereod::sgm
