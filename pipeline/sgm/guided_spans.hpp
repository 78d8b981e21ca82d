#pragma once
// The guided search (a hierarchical SGM, Rothermel et al.'s tSGM): the lanes each
// full-resolution pixel searches, predicted from the coarse level's match (pyramid_sgm.hpp)
// over the whole range, so that the full level searches a narrow span around the
// prediction instead of every disparity.
//
// A coarse pixel's prediction is the span from the smallest to the largest disparity
// measured within kGuideRadius coarse pixels of it (doubled to full-resolution pixels),
// widened by kGuideMarginPx on both sides and rounded out to whole kLaneAlign lanes: at a
// depth edge the window holds both surfaces, so the span covers both. Where the prediction
// is unreliable the span is the whole range:
//  - fewer than kGuideMinMeasured of the window's pixels measured a disparity (flat or
//    occluded areas, thin structures the coarse level lost);
//  - a pixel of the window has its best match at the coarse range's near end (a surface
//    nearer than even the extended range: the full level's own evidence stays complete).
// A prediction beyond the full range (the coarse level measured a surface nearer than the
// full range) searches the full range's last lanes, where the full level finds its near
// end as it would without guidance.
//
// A narrow search cannot reject what a full one rejects: the full search drops a pixel
// whose match has an equal elsewhere in the range (uniqueness, the left-right check) or
// lands in a speckle, and the narrow one never sees those competitors. So a narrow
// pixel's disparity stands only where it agrees within kGuideAgreePx with the coarse
// level's (pyramid_sgm.cpp), a match over the whole range at the same place; and a winner
// at an end of its span that is not an end of the range is dropped (sgm_kernels.hpp): a
// minimum the span cuts is no match. Measured on the 17 shared scenes (docs/configuration.md):
// mean bad-2 and too-far as the full search's, fewer pixels reported (up to 9 points).
//
// The standard library only. Thread-bound: one predictor per matcher; every buffer is
// allocated in the constructor, predict() allocates nothing. With a pool, predict() shares
// the rows out over min(full.threads, its threads) bands (the result is the same).

#include <cstddef>
#include <cstdint>
#include <vector>

#include "pipeline/sgm/band_pool.hpp"
#include "pipeline/sgm/census_sgm.hpp"

namespace stereod::sgm {

// Coarse pixels around a pixel whose disparities make its prediction.
inline constexpr int kGuideRadius = 2;
// Full-resolution pixels a span reaches beyond the disparities it predicts: a coarse
// disparity's error of half a coarse pixel, doubled, with room for the sub-pixel fit.
inline constexpr int kGuideMarginPx = 4;
// Of the (2 kGuideRadius + 1)^2 coarse pixels of the window, how many must have measured
// a disparity for a prediction.
inline constexpr int kGuideMinMeasured = 4;
// Full-resolution pixels within which a narrow pixel's disparity must agree with the
// coarse level's at the same place.
inline constexpr int kGuideAgreePx = 2;

class GuidedSpans {
  public:
    // full, coarse: the two levels' settings (sizes and ranges); full.threads bands at most.
    GuidedSpans(const CensusSgmSettings& full, const CensusSgmSettings& coarse);

    // coarse_disparity: the coarse level's disparities (coarse pixels, +inf where none),
    // coarse_limit: its near-end flags; both coarse width x height. pool: the matcher's
    // band threads, or nullptr: the caller's thread alone.
    void predict(const float* coarse_disparity, const uint8_t* coarse_limit,
                 BandPool* pool = nullptr);

    // The full level's spans, width x height, valid until the next predict().
    const LaneSpan* spans() const { return spans_.data(); }
    // Whether full-resolution pixel i (row-major) searches less than the whole range.
    bool narrow(size_t i) const { return spans_[i].first != 0 || spans_[i].end != units_; }
    // The share of the full level's lanes the last prediction searches, 0..1.
    double searchedShare() const;
    // Bytes of working memory a predictor for these levels allocates.
    static size_t memoryBytes(const CensusSgmSettings& full, const CensusSgmSettings& coarse);

  private:
    // Per coarse pixel, rows of kPad + width + kPad entries: the pads hold a window of no
    // measurement, so that a window is gathered without a test at the image's edges.
    // A window's lanes run lo .. hi (lo below 0: the whole range), `measured` of its
    // pixels measured a disparity.
    struct Windows {
        std::vector<int16_t> lo, hi;
        std::vector<uint8_t> measured;
    };
    static constexpr int kPad = kGuideRadius;

    // Coarse rows y0..y1-1 of own_ (each pixel's own lanes) and along_ (its row's window).
    void gatherRows(const float* coarse_disparity, const uint8_t* coarse_limit, int y0, int y1);
    // Coarse rows y0..y1-1 of the windows down the columns, made into the spans of the
    // full-resolution rows they cover; returns the lanes they search (in kLaneAlign units).
    size_t spanRows(int y0, int y1);

    int width_, height_, coarse_width_, coarse_height_;
    int min_disparity_, num_disparities_, units_;
    int threads_;
    size_t padded_width_;
    Windows own_;   // per coarse pixel: its own lanes
    Windows along_; // per coarse pixel: its row's window
    Windows none_;  // one row of no measurement: the rows above and below the image
    std::vector<LaneSpan> spans_;
    std::vector<size_t> band_searched_; // per band of the last predict()
    double searched_share_ = 1.0;
};

} // namespace stereod::sgm
