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
// allocated in the constructor, predict() allocates nothing.

#include <cstddef>
#include <cstdint>
#include <vector>

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

// Bytes of working memory a predictor for these levels allocates.
class GuidedSpans {
  public:
    // full, coarse: the two levels' settings (sizes and ranges).
    GuidedSpans(const CensusSgmSettings& full, const CensusSgmSettings& coarse);

    // coarse_disparity: the coarse level's disparities (coarse pixels, +inf where none),
    // coarse_limit: its near-end flags; both coarse width x height.
    void predict(const float* coarse_disparity, const uint8_t* coarse_limit);

    // The full level's spans, width x height, valid until the next predict().
    const LaneSpan* spans() const;
    // Whether full-resolution pixel i (row-major) searches less than the whole range.
    bool narrow(size_t i) const;
    // The share of the full level's lanes the last prediction searches, 0..1.
    double searchedShare() const;
    // Bytes of working memory a predictor for these levels allocates.
    static size_t memoryBytes(const CensusSgmSettings& full, const CensusSgmSettings& coarse);

    // A coarse pixel's window, gathered along the row first, then down the columns.
    struct Window {
        int16_t lo = 0;       // smallest lane predicted (below 0: the whole range)
        int16_t hi = 0;       // largest
        uint8_t measured = 0; // pixels with a disparity
    };

  private:
    LaneSpan spanOf(const Window& window) const;

    int width_, height_, coarse_width_, coarse_height_;
    int min_disparity_, num_disparities_, units_;
    std::vector<Window> own_;   // per coarse pixel: its own lanes
    std::vector<Window> along_; // per coarse pixel: its row's window
    std::vector<LaneSpan> coarse_spans_;
    std::vector<LaneSpan> spans_;
    double searched_share_ = 1.0;
};

} // namespace stereod::sgm
