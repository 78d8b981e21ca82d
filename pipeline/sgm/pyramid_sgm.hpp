#pragma once
// census-sgm as the service runs it: the full-resolution match (census_sgm.hpp) and a
// coarse level, the same matcher on the pair halved in each direction, which searches
// twice the disparity range for the price of a quarter of the pixels: the extended range.
// The closest depth the matcher measures halves. (Luxonis DepthAI's "extended disparity"
// is the model: a half-resolution match merged into the full-resolution one.)
//
// Merging, per full-resolution pixel, with the coarse pixel under it (disparities in
// full-resolution pixels, the coarse one doubled):
//  - the coarse level's best match is the near end of its own range: the pixel is near
//    evidence beyond the extended range (kNearerThanExtendedRange);
//  - the coarse level measured, on texture, at or beyond the near end of the full range
//    (within kMergeMarginPx of it): its disparity is taken, with half its confidence (a
//    coarse pixel's half-pixel error is a full-resolution pixel), unless the full level
//    agrees within kMergeMarginPx, whose finer value stays. On a flat patch the coarse
//    level's match says nothing (a flat patch matches any flat patch: a white wall far
//    off would read as a near one);
//  - otherwise the full level's result stands. A pixel whose best match was the full
//    range's near end is evidence of something nearer than the full range
//    (kNearerThanRange), unless a near surface the coarse level measured lies within
//    kExplainRadius coarse pixels: then it is that surface (the flat inside of a near
//    board, whose edges were measured), and takes the nearest disparity measured
//    around it with the confidence kExplainedConfidence.
// Inside the full range the full level decides: the coarse level's edges are a pixel
// wider, and natural scenes keep the accuracy of the full-resolution match. Where the
// full level found nothing, the coarse level's textured match is given apart
// (PyramidSgmOutput::coarse_only_px): not a depth, but what the reading may count.
//
// With the guided search the coarse level runs first, and the full level searches only
// around what it measured (guided_spans.hpp): the whole range where the prediction is
// unreliable, a few dozen disparities elsewhere.
//
// Then the near-field probe (near_field_probe.hpp) looks past the range actually searched
// (the extended one, at the coarse level, or the full one when the extended range is off)
// over the region the reading comes from, and its evidence tiles are marked too.
//
// Thread-bound, like CensusSgm. Both levels' matches, the halving, the merge and the probe
// run in bands on one pool of the pyramid's (settings.full.threads), which rests once a
// compute() is done. All buffers are allocated in the constructor: compute() allocates
// nothing.

#include <cstddef>
#include <cstdint>
#include <memory>

#include "pipeline/sgm/census_sgm.hpp"
#include "pipeline/sgm/near_field_probe.hpp"

namespace stereod::sgm {

// Values of PyramidSgmOutput::near_field. Each says the pixel may show a surface nearer
// than a range reaches: the full-resolution one, or the extended one.
inline constexpr uint8_t kNoNearEvidence = 0;
inline constexpr uint8_t kNearerThanRange = 1;
inline constexpr uint8_t kNearerThanExtendedRange = 2;

// Full-resolution pixels within which the coarse and full levels agree.
inline constexpr int kMergeMarginPx = 2;
// Coarse pixels around a pixel flagged at the full range's near end within which a near
// surface the coarse level measured explains the flag.
inline constexpr int kExplainRadius = 3;
// The confidence of such a pixel, which takes the nearest disparity measured around it:
// inferred, not matched (the lowest but for gap_bridge.hpp's).
inline constexpr uint8_t kExplainedConfidence = 2;

// What the last compute() spent on each part, milliseconds.
struct PyramidSgmTimings {
    double full_ms = 0.0;     // the full-resolution match
    double extended_ms = 0.0; // the coarse level: halving, matching, predicting, merging
    double probe_ms = 0.0;    // the near-field probe
};

struct PyramidSgmSettings {
    CensusSgmSettings full; // the full-resolution level, with the image size
    // The coarse level over twice the range. Off: the full level alone, as CensusSgm.
    bool extended_range = true;
    // With the extended range: the coarse level runs first and the full level searches
    // only the spans it predicts (guided_spans.hpp) rather than the whole range.
    bool guided_search = false;
    // With the guided search: a frame whose spans would search more than this share of the
    // full level's lanes searches the whole range instead, as without the guided search.
    // The spans' kernels cost more per lane than the whole range's, and measured on two
    // cores the guided pipeline was slower from a share of about 0.4 on (bench/README.md).
    double guided_max_share = 0.4;
    // The near-field probe over the region compute() is given.
    bool near_field_probe = true;
};

// The coarse level's settings for a full level's: half the size, the same disparity
// count over half the disparities (so twice the range), the natural scenes' tuning (no
// resolving of periodic patterns, no gap bridging: what it reports beyond the full range
// is taken as measured), speckles a quarter of the area.
CensusSgmSettings coarseLevelSettings(const CensusSgmSettings& full);

// Throws SettingsError naming the field when the settings cannot work.
void validatePyramidSgmSettings(const PyramidSgmSettings& settings);

// Bytes of working memory a matcher with these settings allocates.
size_t pyramidSgmMemoryBytes(const PyramidSgmSettings& settings);

// Where compute() writes; every array is width * height, row-major, caller-owned.
struct PyramidSgmOutput {
    float* disparity_px; // pixels; +inf where nothing trustworthy was found
    uint8_t* confidence; // 0 where invalid, else 1..255 (see docs/protocol.md)
    uint8_t* near_field; // kNoNearEvidence, kNearerThanRange or kNearerThanExtendedRange
    // In the region compute() is given (the reading's), where disparity_px has none: the
    // coarse level's match on texture (full-resolution pixels), +inf elsewhere in the
    // region; outside it, not written. Not part of the depth map (a coarse pixel's edges
    // are a pixel wider); what the reading may count when it brings it nearer. Null: not
    // written.
    float* coarse_only_px = nullptr;
};

class PyramidSgm {
  public:
    // Validates (std::invalid_argument), allocates every buffer and starts the threads.
    explicit PyramidSgm(const PyramidSgmSettings& settings);
    ~PyramidSgm();

    PyramidSgm(const PyramidSgm&) = delete;
    PyramidSgm& operator=(const PyramidSgm&) = delete;

    // left, right: rectified 8-bit images of settings.full.width x height (as
    // CensusSgm::compute()). probe_region: the reading's region, where the near-field probe
    // looks and coarse_only_px is written, full-resolution pixels (clipped to the image;
    // empty: nowhere).
    void compute(const uint8_t* left, size_t left_stride, const uint8_t* right, size_t right_stride,
                 PixelRect probe_region, const PyramidSgmOutput& out);

    const PyramidSgmSettings& settings() const;
    // The largest disparity the full level searches, and the largest the extended range
    // measures (the same without it), full-resolution pixels.
    int fullRangeLast() const;
    int extendedRangeLast() const;
    const PyramidSgmTimings& timings() const;
    // The share of the full level's disparities the last compute() searched, 0..1 (1
    // without the guided search, or when its spans would have searched more than
    // guided_max_share).
    double searchedShare() const;
    // Tiles the near-field probe marked in the last compute(), and tiles it could probe.
    int nearEvidenceTiles() const;
    int probedTiles() const;
    const char* target() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace stereod::sgm
