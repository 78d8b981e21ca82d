#pragma once
// Removes small isolated regions ("speckles") from a disparity image: connected regions
// of valid pixels, neighbours (4-connected) differing by at most max_step, of fewer than
// max_size pixels are set invalid. The same rule as OpenCV's filterSpeckles, without
// allocating: every buffer is sized in the constructor.
//
// A region is found as runs: the pixels of a row that belong together along it, one run
// for each, joined with the runs of the row above that touch it. A surface then costs a
// test per pixel along its rows and one per run across them, and the removal fills runs.
//
// Band-parallel: labelBand() labels the regions inside each band of rows (bands on
// different threads), joinBands() joins the regions that touch across band borders (one
// thread, one pass over the border rows), and removeBand() clears the small ones (bands on
// different threads again). The result does not depend on the bands.
//
// Thread-bound, except that the calls of one phase may run at once on disjoint bands.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace stereod::sgm {

// Bytes a SpeckleFilter for a width x height image allocates.
size_t speckleFilterBytes(int width, int height);

class SpeckleFilter {
  public:
    // width: 1 to 65535 (std::invalid_argument otherwise).
    SpeckleFilter(int width, int height);

    // All three phases on one thread. disparity: width * height values, row-major;
    // `invalid` marks no disparity.
    void apply(int16_t* disparity, int16_t invalid, int max_step, int max_size);

    // Rows y0..y1-1: each region of the band gets its own label and size.
    void labelBand(const int16_t* disparity, int16_t invalid, int max_step, int y0, int y1);
    // After every band is labelled: joins regions across the borders between bands, which
    // start at rows band_starts[1..bands-1]. (The runs already hold only valid pixels.)
    void joinBands(const int16_t* disparity, int max_step, const int* band_starts, int bands);
    // After joinBands(): rows y0..y1-1 lose the pixels of regions of fewer than max_size.
    void removeBand(int16_t* disparity, int16_t invalid, int max_size, int y0, int y1) const;

  private:
    uint32_t root(uint32_t region) const;
    // root(), shortening the chain on the way (labelBand() only: it owns its band's regions).
    uint32_t rootHalving(uint32_t region);
    // Joins two roots into one; returns it.
    uint32_t join(uint32_t a, uint32_t b);
    // Joins each run of row y with the runs of row y - 1 that it touches where a pixel and
    // the one above it belong together.
    void joinRows(const int16_t* disparity, int max_step, int y);

    int width_;
    int height_;
    // Runs of row y: indices y * width .. y * width + runs_[y] - 1; run i covers the pixels
    // begin_[i] .. end_[i] - 1 of its row.
    std::vector<uint32_t> runs_;
    std::vector<uint16_t> begin_;
    std::vector<uint16_t> end_;
    // Per run: the run its region was joined into (itself when none), and its region's
    // pixel count, whole once it is a root.
    std::vector<uint32_t> parent_;
    std::vector<uint32_t> size_;
};

} // namespace stereod::sgm
