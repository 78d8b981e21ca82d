#pragma once
// Census + semi-global matching (Zabih & Woodfill's census transform, Hirschmüller's SGM)
// on rectified 8-bit images: our own matcher, the service's default.
//
// The chain, per frame:
//  1. census transform of both images (window census_width x census_height, each
//     neighbour compared with the centre: up to 64 bits per pixel);
//  2. one row at a time, the Hamming cost of every disparity, and path costs along
//     `paths` directions (3: left->right, right->left, top->bottom; 5 adds the two
//     diagonals from above), all in one top-to-bottom pass, so no W x H x D volume is
//     ever kept: memory grows with W x D;
//  3. winner-takes-all on the summed paths, a uniqueness test against the best
//     non-adjacent disparity, parabolic sub-pixel, the right view's disparity from the
//     same sums and a left-right check;
//  4. a 3x3 median, where asked the disparities of textured pixels that their census does
//     not match dropped, and speckle removal;
//  5. a confidence per pixel, and a flag where the best match sits at the near end of the
//     range (the surface may be nearer than the range can see);
//  6. where asked (man-made scenes): short gaps bridged (gap_bridge.hpp).
//
// The core depends on the standard library and Highway only (no OpenCV), so that it
// builds for any target Highway supports; the kernels (sgm_kernels.hpp) run on SIMD, and
// a scalar reference gives the same disparities bit for bit.
//
// Thread-bound: one CensusSgm serves one caller thread; inside compute() it splits the
// image into horizontal bands over its own `threads` worker threads (started once). Each
// band starts its top-down paths `kBandWarmupRows` rows early so that the bands join
// without a visible seam. All buffers are allocated in the constructor: compute()
// allocates nothing.

#include <cstdint>
#include <memory>
#include <string>

#include "pipeline/sgm/sgm_kernels.hpp"

namespace stereod::sgm {

// The most disparities one search covers: a lane index fits a byte.
inline constexpr int kMaxDisparities = 256;

struct CensusSgmSettings {
    int width = 0; // image size in pixels
    int height = 0;
    int min_disparity = 0;    // disparities min_disparity .. + num_disparities - 1
    int num_disparities = 64; // a multiple of 16, 16..kMaxDisparities
    // The defaults below were chosen on 17 real scenes with ground truth (Middlebury 2001,
    // 2005, 2014, KITTI 2012, ETH3D): fewest wrong and too-far pixels for a density close
    // to OpenCV SGBM's. An 11x3 census (32 bits: four byte planes) resists repetitive
    // texture better than 7x5 (34 bits, five planes) and costs less.
    int census_width = 11; // odd; census_width * census_height - 1 <= 64 bits
    int census_height = 3; // odd
    int paths = 3;         // 3 or 5 (see above); 5 measured no better
    int p1 = 16;           // penalty for a 1 px disparity step, census bits
    int p2 = 160;          // penalty for a larger step, before adaptation
    // P2 is lowered where the image changes along the path (a likely depth edge):
    // P2 / (1 + |dI| / p2_gradient_scale), never below p1 + 1. 0 turns adaptation off.
    int p2_gradient_scale = 3;
    int uniqueness_percent = 9;  // best non-adjacent sum must exceed best by this much
    int lr_max_diff_px = 2;      // left-right check tolerance; < 0 turns it off
    bool median = true;          // 3x3 median of the disparities
    int speckle_window_px = 200; // smaller connected regions are removed; 0: off
    int speckle_range_px = 1;    // disparity step allowed inside a region
    // Pixels whose search range is cut by the left image edge (x < min_disparity +
    // num_disparities - 1) keep a disparity only when it lies this far below the cut.
    int edge_margin_px = 4;
    // Runs of at most this many pixels without disparity, along a row or a column, between
    // two disparities within 1 px of each other get the line between them (gap_bridge.hpp);
    // 0: off. For man-made scenes of uniform planar surfaces.
    int gap_fill_px = 0;
    // Where the middle of the census window (5x3 px) has texture, an intensity range of at
    // least textured_min_range grey levels, a disparity whose census cost exceeds
    // textured_max_cost bits (at the whole disparity below and above it) is dropped: the
    // census tells matches apart there, so a bad one means the disparity came from the
    // paths alone. Without it, paths that keep P2 high across edges (p2_gradient_scale
    // 0) carry the disparity around a surface nearer than the range into it. < 0: off.
    int textured_max_cost = -1;
    int textured_min_range = 20;
    // Where a row runs through a pattern that repeats along it (periodic_pattern.hpp):
    // there P2 keeps its full height across edges (so the paths carry what the pattern's
    // ends say), the best match need be only periodic_uniqueness_percent better than the
    // next, a textured pixel whose census does not match its disparity within
    // periodic_textured_max_cost bits is dropped (as textured_max_cost does everywhere),
    // and gaps of up to periodic_gap_fill_px inside the pattern are bridged. Elsewhere the
    // settings above hold. false: no pattern is looked for.
    bool periodic_patterns = false;
    int periodic_uniqueness_percent = 2;
    int periodic_textured_max_cost = 8;
    int periodic_gap_fill_px = 15;
    int threads = 1;      // worker threads inside compute()
    bool use_simd = true; // false: the scalar reference kernels
};

// The defaults above: for natural, textured scenes (`matcher.tuning: natural`).
inline constexpr CensusSgmSettings kNaturalSceneSettings{};

// The settings for man-made scenes of uniform flat surfaces and repeating patterns
// (`matcher.tuning: planar`; the defaults above are those for natural scenes). On a
// uniform, repeating pattern (a chessboard) a row matches about as well one period off;
// what tells the periods apart is the pattern's ends, and the paths carry that along the
// row only if P2 keeps its full height at every edge of the pattern: no gradient
// adaptation, which on natural scenes is what keeps depth edges sharp. Those paths would
// also carry the disparity around a surface nearer than the range into it: where the
// census sees texture, a disparity it does not match is dropped. Short gaps between
// agreeing disparities (a uniform square's inside, the edge between two squares) are
// bridged. Tuned on a real rig's chessboard (opencv-doc's 13 pairs).
inline constexpr CensusSgmSettings kPlanarSceneSettings = [] {
    CensusSgmSettings s;
    s.p2_gradient_scale = 0;
    s.uniqueness_percent = 2;
    s.speckle_window_px = 400;
    s.speckle_range_px = 2;
    s.gap_fill_px = 15;
    s.textured_max_cost = 8;
    return s;
}();

// The natural scenes' settings, and inside a pattern that repeats along the rows the
// planar tuning's steps (`matcher.tuning: patterns`): one matcher for scenes that hold
// both. Measured on the real rig's chessboard and the 17 natural scenes, it lies between
// the two tunings (docs/configuration.md).
inline constexpr CensusSgmSettings kPatternSceneSettings = [] {
    CensusSgmSettings s;
    s.periodic_patterns = true;
    return s;
}();

// Throws SettingsError naming the field when the settings cannot work. A size
// of 0x0 skips the checks that need the image size.
void validateCensusSgmSettings(const CensusSgmSettings& settings);

// Where compute() writes; every array is width * height, row-major, caller-owned.
struct CensusSgmOutput {
    float* disparity_px;  // pixels; +inf where nothing trustworthy was found
    uint8_t* confidence;  // 0 where invalid, else 1..255 (see docs/protocol.md)
    uint8_t* range_limit; // 1 where the best match is at the near end of the range
};

// Bytes of working memory a matcher with these settings allocates.
size_t censusSgmMemoryBytes(const CensusSgmSettings& settings);

// Pointers to one row of the census images of both views (CensusSgm::censusRows()), and
// the CensusRows that the kernels take, pointing into them.
struct CensusRowPointers {
    const uint8_t* left[8];
    const uint8_t* right[8];
    const uint8_t* right_reversed[8];
    CensusRows rows{left, right, right_reversed, 0};
};

class BandPool;

class CensusSgm {
  public:
    // Validates (std::invalid_argument), allocates every buffer and starts the threads:
    // its own, or those of `pool` when given (at least settings.threads of them), which
    // must outlive it and be called from the same thread (several levels of one matcher
    // share one pool, so that its threads stay warm from one level to the next).
    explicit CensusSgm(const CensusSgmSettings& settings, BandPool* pool = nullptr);
    ~CensusSgm();

    CensusSgm(const CensusSgm&) = delete;
    CensusSgm& operator=(const CensusSgm&) = delete;

    // left, right: rectified 8-bit images of settings.width x settings.height, their rows
    // left_stride and right_stride bytes apart (two views of one frame, or copies, need
    // not agree). spans: width x height, the lanes each pixel searches (a guided search,
    // sgm_kernels.hpp; first < end <= lane count / kLaneAlign), or nullptr: every lane.
    void compute(const uint8_t* left, size_t left_stride, const uint8_t* right, size_t right_stride,
                 const CensusSgmOutput& out, const LaneSpan* spans = nullptr);

    const CensusSgmSettings& settings() const;
    // Row y of the census images the last compute() made (both views, and the right one
    // reversed), valid until the next compute(): for the near-field probe.
    void censusRows(int y, CensusRowPointers& out) const;
    const SgmKernels& kernels() const;
    // The kernels' target: "AVX2", "SSE4", "NEON", ..., or "scalar".
    const char* target() const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

} // namespace stereod::sgm
