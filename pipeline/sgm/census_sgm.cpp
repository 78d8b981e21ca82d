#include "pipeline/sgm/census_sgm.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/settings_error.hpp"
#include "pipeline/sgm/band_pool.hpp"
#include "pipeline/sgm/gap_bridge.hpp"
#include "pipeline/sgm/periodic_pattern.hpp"
#include "pipeline/sgm/speckle_filter.hpp"
#include "pipeline/sgm/texture.hpp"

namespace stereod::sgm {
namespace {

// Rows a band runs its top-down paths before its first own row. Past about 24 rows the
// path costs no longer depend on where the path started (measured: the disparities of a
// 2-band run equal a 1-band run's on 99.9 % of the pixels with 32 rows).
constexpr int kBandWarmupRows = 32;
// A warm-up row's work (its costs and the paths from above) against a whole row's (also
// the path along the row, the winners and the decision), measured by perf at 128
// disparities: the cost rows 10 %, the forward paths 16 % of which the path along the
// row a third, the winners 31 %, the decision 2.4 % of a frame's samples.
constexpr double kWarmupRowShare = 0.35;

[[noreturn]] void invalid(const std::string& key, const std::string& problem)
{
    throw SettingsError(key, problem);
}

int roundUp(int value, int step)
{
    return (value + step - 1) / step * step;
}

int censusBits(const CensusSgmSettings& s)
{
    return s.census_width * s.census_height - 1;
}

// The work of one band: its rows' costs and paths. Sized once for the widest row.
struct BandScratch {
    std::vector<uint8_t> cost;         // width * lanes
    std::vector<uint8_t> forward;      // width path blocks: the left->right path
    std::vector<uint8_t> row_scratch;  // two path blocks: the right->left path
    std::vector<uint16_t> sum_scratch; // summed paths of a few pixels
    std::vector<uint8_t> above[3][2];  // per path from above: previous, current row
    std::vector<uint8_t> p2_above[3];  // width, per path from above
    // width + 1: P2 onto x from x - 1 at [x], so onto x from x + 1 at [x + 1].
    std::vector<uint8_t> p2_along;
    std::vector<uint16_t> winner_fields; // the five rows of WinnerRows, width each
    WinnerRows winners{};
    std::vector<uint16_t> right_lane; // rightLaneEntries()
    std::vector<uint16_t> winners_scratch;
    std::vector<uint8_t> edge_state; // width: dropFlatBetweenUnmatchedEdges()
    std::vector<int> edges;          // 2 * width: markPeriodicRows()
};

} // namespace

void validateCensusSgmSettings(const CensusSgmSettings& s)
{
    const bool sized = s.width != 0 || s.height != 0; // 0x0: the size is not known yet
    if (sized && (s.width < 1 || s.height < 1))
        invalid("size", "the image must be at least 1x1, got " + std::to_string(s.width) + "x" +
                            std::to_string(s.height));
    if (s.num_disparities < 16 || s.num_disparities > kMaxDisparities ||
        s.num_disparities % 16 != 0)
        invalid("num_disparities", "must be a multiple of 16 within 16.." +
                                       std::to_string(kMaxDisparities) + " for census-sgm, got " +
                                       std::to_string(s.num_disparities));
    if (s.min_disparity < -1024 || s.min_disparity > 1024)
        invalid("min_disparity",
                "must be within -1024..1024, got " + std::to_string(s.min_disparity));
    if (s.census_width < 3 || s.census_width % 2 == 0 || s.census_height < 1 ||
        s.census_height % 2 == 0)
        invalid("census", "window sides must be odd, at least 3x1, got " +
                              std::to_string(s.census_width) + "x" +
                              std::to_string(s.census_height));
    if (censusBits(s) > 64)
        invalid("census", "window " + std::to_string(s.census_width) + "x" +
                              std::to_string(s.census_height) + " has more than 64 neighbours");
    if (s.paths != 3 && s.paths != 5)
        invalid("paths", "must be 3 or 5, got " + std::to_string(s.paths));
    if (s.p1 < 1 || s.p2 <= s.p1)
        invalid("p2", "must be greater than p1 >= 1, got p1 " + std::to_string(s.p1) + ", p2 " +
                          std::to_string(s.p2));
    // 8-bit path costs: the largest census cost plus P2 must stay within 255.
    if (censusBits(s) + s.p2 > 255)
        invalid("p2", "census cost " + std::to_string(censusBits(s)) + " + p2 " +
                          std::to_string(s.p2) + " must be <= 255");
    if (s.p2_gradient_scale < 0)
        invalid("p2_gradient_scale",
                "must be >= 0 (0: no adaptation), got " + std::to_string(s.p2_gradient_scale));
    if (s.uniqueness_percent < 0 || s.uniqueness_percent > 100)
        invalid("uniqueness_ratio",
                "must be within 0..100, got " + std::to_string(s.uniqueness_percent));
    if (s.speckle_window_px < 0 || s.speckle_range_px < 0)
        invalid("speckle_window_px", "speckle window and range must be >= 0");
    if (s.gap_fill_px < 0)
        invalid("gap_fill_px", "must be >= 0, got " + std::to_string(s.gap_fill_px));
    if (s.textured_max_cost > censusBits(s))
        invalid("textured_max_cost", "must be at most the census's " +
                                         std::to_string(censusBits(s)) + " bits, got " +
                                         std::to_string(s.textured_max_cost));
    if (s.textured_min_range < 0 || s.textured_min_range > 255)
        invalid("textured_min_range",
                "must be within 0..255 grey levels, got " + std::to_string(s.textured_min_range));
    if (s.periodic_uniqueness_percent < 0 || s.periodic_uniqueness_percent > 100)
        invalid("periodic_uniqueness_percent",
                "must be within 0..100, got " + std::to_string(s.periodic_uniqueness_percent));
    if (s.periodic_textured_max_cost < 0 || s.periodic_textured_max_cost > censusBits(s))
        invalid("periodic_textured_max_cost", "must be within 0.." + std::to_string(censusBits(s)) +
                                                  " census bits, got " +
                                                  std::to_string(s.periodic_textured_max_cost));
    if (s.periodic_gap_fill_px < 0)
        invalid("periodic_gap_fill_px",
                "must be >= 0, got " + std::to_string(s.periodic_gap_fill_px));
    if (s.edge_margin_px < 0)
        invalid("edge_margin_px", "must be >= 0, got " + std::to_string(s.edge_margin_px));
    if (s.threads < 1 || s.threads > 64)
        invalid("threads", "must be within 1..64, got " + std::to_string(s.threads));
    if (sized && (s.census_height / 2 >= s.height || s.census_width / 2 >= s.width))
        invalid("census", "window does not fit in the image");
}

size_t censusSgmMemoryBytes(const CensusSgmSettings& s)
{
    const size_t w = static_cast<size_t>(s.width);
    const size_t h = static_cast<size_t>(s.height);
    const size_t lanes = static_cast<size_t>(roundUp(s.num_disparities, kLaneAlign));
    const size_t planes = static_cast<size_t>((censusBits(s) + 7) / 8);
    const size_t padded =
        (w + static_cast<size_t>(s.census_width)) * (h + static_cast<size_t>(s.census_height));
    const size_t image = 2 * padded + 3 * planes * w * h;     // padded inputs, census
    const size_t output = w * h * (2 * sizeof(int16_t) + 2) + // fixed point x2, conf, flags
                          speckleFilterBytes(s.width, s.height);
    const size_t above = s.paths == 5 ? 3 : 1;
    const size_t band =
        w * lanes + 2 * pathBlockBytes(static_cast<int>(lanes)) +
        winnersSumScratch(static_cast<int>(lanes)) * sizeof(uint16_t) +
        (above * 2 + 1) * w * pathBlockBytes(static_cast<int>(lanes)) + w * (above + 1) + 1 +
        (5 * w + rightLaneEntries(s.width)) * sizeof(uint16_t) +
        winnersScratch(s.width, s.min_disparity, static_cast<int>(lanes)) * sizeof(uint16_t);
    // The pattern masks (raw and spread) and each band's edge lists.
    const size_t patterns = s.periodic_patterns ? 2 * w * h : 0;
    const size_t edges = s.periodic_patterns ? 2 * w * sizeof(int) : 0;
    return image + output + patterns + (band + edges) * static_cast<size_t>(s.threads);
}

struct CensusSgm::Impl {
    Impl(const CensusSgmSettings& s, BandPool* shared_pool)
        : settings(s), kernels(s.use_simd ? &simdKernels() : &scalarKernels()),
          lanes(roundUp(s.num_disparities, kLaneAlign)), planes((censusBits(s) + 7) / 8),
          rx(s.census_width / 2), ry(s.census_height / 2),
          padded_stride(static_cast<size_t>(s.width + 2 * rx)),
          own_pool(shared_pool != nullptr ? nullptr : std::make_unique<BandPool>(s.threads)),
          pool(shared_pool != nullptr ? *shared_pool : *own_pool), speckle(s.width, s.height)
    {
        const size_t area = static_cast<size_t>(s.width) * static_cast<size_t>(s.height);
        const size_t padded_rows = static_cast<size_t>(s.height + 2 * ry);
        padded_left.assign(padded_stride * padded_rows, 0);
        padded_right.assign(padded_stride * padded_rows, 0);
        // Each census plane has a margin before and after it: the SIMD cost kernel reads
        // a little outside the row for the lanes whose right pixel is outside the image.
        plane_margin = static_cast<size_t>(lanes + std::abs(s.min_disparity) + 2 * kLaneAlign);
        plane_stride = area + 2 * plane_margin;
        census_left.assign(plane_stride * static_cast<size_t>(planes), 0);
        census_right.assign(plane_stride * static_cast<size_t>(planes), 0);
        census_right_reversed.assign(plane_stride * static_cast<size_t>(planes), 0);
        fixed.assign(area, kNoDisparity);
        filtered.assign(area, kNoDisparity);

        const size_t row_cells = static_cast<size_t>(s.width) * static_cast<size_t>(lanes);
        const size_t row_blocks = static_cast<size_t>(s.width) * pathBlockBytes(lanes);
        bands.resize(static_cast<size_t>(s.threads));
        for (BandScratch& b : bands) {
            // Path blocks start all 255: their pads stay so (see sgm_kernels.hpp).
            b.cost.assign(row_cells, 0);
            b.forward.assign(row_blocks, 255);
            b.row_scratch.assign(2 * pathBlockBytes(lanes), 255);
            b.sum_scratch.assign(winnersSumScratch(lanes), 0);
            for (int i = 0; i < abovePaths(); ++i) {
                b.above[i][0].assign(row_blocks, 255);
                b.above[i][1].assign(row_blocks, 255);
                b.p2_above[i].assign(static_cast<size_t>(s.width), 0);
            }
            b.p2_along.assign(static_cast<size_t>(s.width) + 1, 0);
            const size_t w = static_cast<size_t>(s.width);
            b.winner_fields.assign(5 * w, 0);
            uint16_t* f = b.winner_fields.data();
            b.winners = WinnerRows{f, f + w, f + 2 * w, f + 3 * w, f + 4 * w};
            b.right_lane.assign(rightLaneEntries(s.width), 0);
            b.winners_scratch.assign(winnersScratch(s.width, s.min_disparity, lanes), 0);
            b.edge_state.assign(static_cast<size_t>(s.width), 0);
            if (s.periodic_patterns)
                b.edges.assign(2 * static_cast<size_t>(s.width), 0);
        }
        if (s.periodic_patterns) {
            periodic_raw.assign(area, 0);
            periodic.assign(area, 0);
        }
        decide = DecideSettings{s.min_disparity,     s.num_disparities,
                                decideUniqueness(s), s.lr_max_diff_px,
                                s.edge_margin_px,    static_cast<float>(2 * s.p1 * s.paths)};
        // P2 by intensity step along the path (see CensusSgmSettings::p2_gradient_scale).
        for (int g = 0; g < 256; ++g) {
            double p2 = s.p2;
            if (s.p2_gradient_scale > 0)
                p2 = s.p2 / (1.0 + static_cast<double>(g) / s.p2_gradient_scale);
            p2_by_step[g] =
                static_cast<uint8_t>(std::clamp(static_cast<int>(std::lround(p2)), s.p1 + 1, s.p2));
        }
        // The kernel's short table serves where P2 no longer changes past its last step
        // (at the floor p1 + 1, or everywhere without adaptation).
        short_steps = std::all_of(p2_by_step + kPenaltySteps, p2_by_step + 256,
                                  [&](uint8_t p2) { return p2 == p2_by_step[kPenaltySteps - 1]; });
    }

    int abovePaths() const { return settings.paths == 5 ? 3 : 1; }

    static int decideUniqueness(const CensusSgmSettings& s)
    {
        return s.periodic_patterns ? std::min(s.uniqueness_percent, s.periodic_uniqueness_percent)
                                   : s.uniqueness_percent;
    }

    const uint8_t* periodicRow(int y) const
    {
        return periodic.empty()
                   ? nullptr
                   : periodic.data() + static_cast<size_t>(y) * static_cast<size_t>(settings.width);
    }

    // Copies an image into its padded buffer, replicating the border pixels.
    void pad(const uint8_t* image, size_t stride, std::vector<uint8_t>& padded, int y0, int y1)
    {
        const int w = settings.width;
        for (int py = y0; py < y1; ++py) {
            const int y = std::clamp(py - ry, 0, settings.height - 1);
            const uint8_t* src = image + static_cast<size_t>(y) * stride;
            uint8_t* dst = padded.data() + static_cast<size_t>(py) * padded_stride;
            std::fill(dst, dst + rx, src[0]);
            std::copy(src, src + w, dst + rx);
            std::fill(dst + rx + w, dst + 2 * rx + w, src[w - 1]);
        }
    }

    // Row y of census plane p.
    const uint8_t* planeRow(const std::vector<uint8_t>& census, int p, int y) const
    {
        return census.data() + static_cast<size_t>(p) * plane_stride + plane_margin +
               static_cast<size_t>(y) * static_cast<size_t>(settings.width);
    }
    uint8_t* planeRow(std::vector<uint8_t>& census, int p, int y) const
    {
        return census.data() + static_cast<size_t>(p) * plane_stride + plane_margin +
               static_cast<size_t>(y) * static_cast<size_t>(settings.width);
    }

    void censusRows(const std::vector<uint8_t>& padded, std::vector<uint8_t>& census, int y0,
                    int y1)
    {
        uint8_t* plane_rows[8];
        for (int y = y0; y < y1; ++y) {
            for (int p = 0; p < planes; ++p)
                plane_rows[p] = planeRow(census, p, y);
            const uint8_t* center = padded.data() + static_cast<size_t>(y + ry) * padded_stride +
                                    static_cast<size_t>(rx);
            kernels->census_row(center, padded_stride, settings.width, settings.census_width,
                                settings.census_height, plane_rows);
        }
    }

    void reverseRightRows(int y0, int y1)
    {
        const int w = settings.width;
        for (int y = y0; y < y1; ++y)
            for (int p = 0; p < planes; ++p) {
                const uint8_t* row = planeRow(census_right, p, y);
                uint8_t* reversed = planeRow(census_right_reversed, p, y);
                // Eight bytes at a time, swapped end for end.
                int j = 0;
                for (; j + 8 <= w; j += 8) {
                    uint64_t bytes;
                    std::memcpy(&bytes, row + w - j - 8, 8);
                    bytes = byteSwap(bytes);
                    std::memcpy(reversed + j, &bytes, 8);
                }
                for (; j < w; ++j)
                    reversed[j] = row[w - 1 - j];
            }
    }

    static uint64_t byteSwap(uint64_t v)
    {
        v = ((v & 0x00FF00FF00FF00FFull) << 8) | ((v >> 8) & 0x00FF00FF00FF00FFull);
        v = ((v & 0x0000FFFF0000FFFFull) << 16) | ((v >> 16) & 0x0000FFFF0000FFFFull);
        return (v << 32) | (v >> 32);
    }

    // p2[x] = P2 for the step between a[x] and b[x], x in 0..n-1: by the kernel's short
    // table where P2 no longer changes past its last step, else by the whole table.
    void penaltiesOfSteps(const uint8_t* a, const uint8_t* b, int n, uint8_t* p2) const
    {
        if (short_steps) {
            kernels->step_penalties(a, b, n, p2_by_step, p2);
            return;
        }
        for (int x = 0; x < n; ++x)
            p2[x] = p2_by_step[std::abs(static_cast<int>(a[x]) - static_cast<int>(b[x]))];
    }

    // The P2 of every pixel of row y for a step from (x + dx, y - 1) onto (x, y); a step
    // from outside the image counts as no intensity change.
    void penaltiesFromAbove(const uint8_t* left, size_t stride, int y, int dx, uint8_t* p2) const
    {
        const int w = settings.width;
        const uint8_t* row = left + static_cast<size_t>(y) * stride;
        const uint8_t* from = left + static_cast<size_t>(std::max(y - 1, 0)) * stride;
        const int x0 = std::max(0, -dx);
        const int x1 = std::min(w, w - dx);
        for (int x = 0; x < x0; ++x)
            p2[x] = p2_by_step[std::abs(static_cast<int>(row[x]) - static_cast<int>(from[0]))];
        penaltiesOfSteps(row + x0, from + x0 + dx, x1 - x0, p2 + x0);
        for (int x = x1; x < w; ++x)
            p2[x] = p2_by_step[std::abs(static_cast<int>(row[x]) - static_cast<int>(from[w - 1]))];
    }

    // p2[x] = P2 for a step between x - 1 and x of row y, for x in 0..width (0 and width:
    // outside the image, no intensity change).
    void penaltiesAlong(const uint8_t* left, size_t stride, int y, uint8_t* p2) const
    {
        const int w = settings.width;
        const uint8_t* row = left + static_cast<size_t>(y) * stride;
        p2[0] = p2_by_step[0];
        penaltiesOfSteps(row + 1, row, w - 1, p2 + 1);
        p2[w] = p2_by_step[0];
    }

    // The first row of band `band` of the match (settings.height for band == threads).
    // Every band after the first runs kBandWarmupRows rows of paths from above before its
    // own: the first band takes as many more rows as that work, so that all the bands
    // finish together (with equal rows, the caller's band waited 4 % of the match for
    // the other's).
    int matchBandStart(int band) const
    {
        const int h = settings.height, threads = settings.threads;
        if (band <= 0)
            return 0;
        if (band >= threads)
            return h;
        const double warmup = kBandWarmupRows * kWarmupRowShare;
        const double share = (h + (threads - 1) * warmup) / threads;
        int start = 0;
        for (int k = 1; k <= band; ++k) {
            const double at = share + (k - 1) * (share - warmup);
            start = std::clamp(static_cast<int>(std::lround(at)), start, h);
        }
        return start;
    }

    void matchBand(int band, const uint8_t* left, size_t stride, const LaneSpan* spans,
                   const CensusSgmOutput& out)
    {
        const CensusSgmSettings& s = settings;
        BandScratch& b = bands[static_cast<size_t>(band)];
        const int y0 = matchBandStart(band);
        const int y1 = matchBandStart(band + 1);
        const int first_row = std::max(0, y0 - kBandWarmupRows);
        const uint8_t* left_planes[8];
        const uint8_t* right_planes[8];
        const uint8_t* right_reversed[8];
        static constexpr int kAboveDx[3] = {0, -1, 1};
        const int above = abovePaths();
        const uint8_t cost_invalid = static_cast<uint8_t>(censusBits(s));

        for (int y = first_row; y < y1; ++y) {
            for (int p = 0; p < planes; ++p) {
                left_planes[p] = planeRow(census_left, p, y);
                right_planes[p] = planeRow(census_right, p, y);
                right_reversed[p] = planeRow(census_right_reversed, p, y);
            }
            const CensusRows rows{left_planes, right_planes, right_reversed, planes};
            const size_t row = static_cast<size_t>(y) * static_cast<size_t>(s.width);
            const LaneSpan* row_spans = spans != nullptr ? spans + row : nullptr;
            const LaneSpan* prev_spans =
                spans != nullptr && y > first_row ? row_spans - s.width : nullptr;
            kernels->cost_row(rows, s.width, s.min_disparity, s.num_disparities, lanes,
                              cost_invalid, b.cost.data(), row_spans);

            const int parity = (y - first_row) & 1;
            const uint8_t* others[4];
            const uint8_t* p2_rows[3];
            const uint8_t* prev_rows[3];
            uint8_t* cur_rows[3];
            for (int i = 0; i < above; ++i) {
                penaltiesFromAbove(left, stride, y, kAboveDx[i], b.p2_above[i].data());
                if (s.periodic_patterns)
                    keepFullP2(periodicRow(y), b.p2_above[i].data(), 0);
                p2_rows[i] = b.p2_above[i].data();
                prev_rows[i] = y == first_row ? nullptr : b.above[i][parity ^ 1].data();
                cur_rows[i] = b.above[i][parity].data();
                others[i] = cur_rows[i];
            }
            const AbovePaths above_paths{above, kAboveDx, p2_rows, prev_rows, cur_rows, prev_spans};
            if (y < y0) {
                // Warming up the paths from above for this band's first row.
                kernels->paths_forward(b.cost.data(), static_cast<uint8_t>(s.p1), s.width, lanes,
                                       above_paths, nullptr, nullptr, row_spans);
                continue;
            }
            penaltiesAlong(left, stride, y, b.p2_along.data());
            if (s.periodic_patterns)
                keepFullP2(periodicRow(y), b.p2_along.data(), 1);
            kernels->paths_forward(b.cost.data(), static_cast<uint8_t>(s.p1), s.width, lanes,
                                   above_paths, b.p2_along.data(), b.forward.data(), row_spans);
            others[above] = b.forward.data();
            kernels->winners_backward(
                b.cost.data(), b.p2_along.data() + 1, static_cast<uint8_t>(s.p1), s.width, lanes,
                PathRows{others, above + 1}, s.min_disparity, s.num_disparities,
                b.row_scratch.data(), b.sum_scratch.data(), b.winners, b.right_lane.data(),
                b.winners_scratch.data(), row_spans);
            kernels->decide_row(b.winners, b.right_lane.data(), s.width, decide, fixed.data() + row,
                                out.confidence + row, out.range_limit + row);
            if (decide.uniqueness_percent != s.uniqueness_percent)
                holdUniqueness(b.winners, periodicRow(y), fixed.data() + row, out.confidence + row);
        }
    }

    // P2 at its full height where a repeating pattern runs (periodic_pattern.hpp): p2[x]
    // is the step onto pixel x - shift (0 for the paths from above, 1 along the row, whose
    // p2[x] is the step from x - 1 onto x: full when either end lies in the pattern).
    void keepFullP2(const uint8_t* mask, uint8_t* p2, int shift) const
    {
        const int w = settings.width;
        const auto full = static_cast<uint8_t>(settings.p2);
        for (int x = 0; x < w; ++x)
            if (mask[x] != 0)
                p2[x + shift] = full;
        if (shift != 0)
            for (int x = 1; x < w; ++x)
                if (mask[x - 1] != 0)
                    p2[x] = full;
    }

    // Outside a repeating pattern, the uniqueness the settings ask for: decide_row() took
    // the pattern's lower one for every pixel.
    void holdUniqueness(const WinnerRows& w, const uint8_t* mask, int16_t* disparity,
                        uint8_t* confidence) const
    {
        const auto margin = static_cast<uint32_t>(100 + settings.uniqueness_percent);
        for (int x = 0; x < settings.width; ++x) {
            if (disparity[x] == kNoDisparity || mask[x] != 0)
                continue;
            if (static_cast<uint32_t>(w.second_sum[x]) * 100u <=
                static_cast<uint32_t>(w.best_sum[x]) * margin) {
                disparity[x] = kNoDisparity;
                confidence[x] = 0;
            }
        }
    }

    // 3x3 median around each valid pixel, rows y0..y1-1; a missing neighbour counts as
    // the centre's value, so that holes neither pull a disparity down (too far) nor up.
    // The one-pixel image border is copied as it is.
    void medianRows(int y0, int y1)
    {
        const int w = settings.width, h = settings.height;
        for (int y = y0; y < y1; ++y) {
            const size_t at = static_cast<size_t>(y) * static_cast<size_t>(w);
            const int16_t* row = fixed.data() + at;
            int16_t* dst = filtered.data() + at;
            if (y == 0 || y == h - 1 || w < 3) {
                std::copy(row, row + w, dst);
                continue;
            }
            dst[0] = row[0];
            dst[w - 1] = row[w - 1];
            kernels->median_row(row - w, row, row + w, w, kNoDisparity, dst);
        }
    }

    // Rows y0..y1-1 lose the disparities of textured pixels that their census does not
    // match (CensusSgmSettings::textured_max_cost); only those of confidence
    // kInferredConfidence when `inferred` is given (after bridging: the others passed).
    void dropUnmatchedTexture(std::vector<int16_t>& disparity, const uint8_t* left, size_t stride,
                              int y0, int y1, const uint8_t* inferred, uint8_t* range_limit)
    {
        const int w = settings.width, h = settings.height;
        const int max_cost = textureMaxCost();
        for (int y = y0; y < y1; ++y) {
            const size_t row = static_cast<size_t>(y) * static_cast<size_t>(w);
            const uint8_t* mask = settings.textured_max_cost >= 0 ? nullptr : periodicRow(y);
            for (int x = 0; x < w; ++x) {
                int16_t& d = disparity[row + static_cast<size_t>(x)];
                if (d == kNoDisparity || (mask != nullptr && mask[x] == 0) ||
                    (inferred != nullptr &&
                     inferred[row + static_cast<size_t>(x)] != kInferredConfidence))
                    continue;
                // The whole disparities around the sub-pixel one (floor and ceiling). Most
                // pixels match: the texture is looked at only for those that do not.
                const int lower = d >> 4;
                const int upper = (d + kSubpixel - 1) >> 4;
                static_assert(kSubpixel == 16);
                int cost = INT32_MAX;
                for (const int whole : {lower, upper}) {
                    const int xr = x - whole;
                    if (xr >= 0 && xr < w)
                        cost = std::min(cost, censusCost(x, xr, y));
                }
                if (cost != INT32_MAX && cost > max_cost &&
                    isTextured(left, stride, w, h, x, y, settings.textured_min_range)) {
                    d = kNoDisparity;
                    // A textured pixel that matches nothing in the range is evidence of a
                    // surface nearer than it (pyramid_sgm.hpp), as one whose best match is
                    // the range's near end is.
                    if (range_limit != nullptr && !matchesInRange(x, y))
                        range_limit[row + static_cast<size_t>(x)] = 1;
                }
            }
        }
    }

    // The texture check's threshold: everywhere, or inside repeating patterns only.
    int textureMaxCost() const
    {
        return settings.textured_max_cost >= 0 ? settings.textured_max_cost
                                               : settings.periodic_textured_max_cost;
    }

    // Whether left pixel (x, y) matches some disparity of the range within
    // textured_max_cost bits.
    bool matchesInRange(int x, int y)
    {
        const int first = std::max(settings.min_disparity, x - (settings.width - 1));
        const int last = std::min(settings.min_disparity + settings.num_disparities - 1, x);
        for (int d = first; d <= last; ++d)
            if (censusCost(x, x - d, y) <= textureMaxCost())
                return true;
        return false;
    }

    // Rows y0..y1-1 lose the disparities of flat stretches (no texture) whose textured
    // ends, along the row, have no disparity and one of them matches nothing in the
    // range: paths that keep P2 high carry a disparity across a flat patch from around it,
    // and when the patch's own edges match nothing the range holds, the patch is nearer
    // than the range (a uniform box would read as the wall behind it). The stretch is
    // flagged as its edge is. Edges that match something in the range but not the
    // disparity carried there (a periodic pattern's) leave it alone: the patch is in the
    // range. Runs after dropUnmatchedTexture(), which flags the edges.
    void dropFlatBetweenUnmatchedEdges(std::vector<int16_t>& disparity, const uint8_t* left,
                                       size_t stride, int y0, int y1, uint8_t* edge_state,
                                       uint8_t* range_limit)
    {
        // edge_state[x]: the nearest textured pixel at or before x, along the row: 0 none,
        // 1 with a disparity, 2 without, 3 matching nothing in the range (flagged). A flat
        // stretch dropped beside an edge that matches nothing in the range is flagged too:
        // it is that edge's surface.
        const int w = settings.width, h = settings.height;
        for (int y = y0; y < y1; ++y) {
            const size_t row = static_cast<size_t>(y) * static_cast<size_t>(w);
            const uint8_t* mask = settings.textured_max_cost >= 0 ? nullptr : periodicRow(y);
            if (mask != nullptr && std::find(mask, mask + w, uint8_t{1}) == mask + w)
                continue; // no pattern in this row: nothing to check
            uint8_t state = 0;
            const auto edge = [&](int x) -> uint8_t {
                const size_t i = row + static_cast<size_t>(x);
                return disparity[i] != kNoDisparity ? 1 : range_limit[i] != 0 ? 3 : 2;
            };
            for (int x = 0; x < w; ++x) {
                if (isTextured(left, stride, w, h, x, y, settings.textured_min_range))
                    state = edge(x);
                edge_state[static_cast<size_t>(x)] = state;
            }
            state = 0;
            for (int x = w - 1; x >= 0; --x) {
                int16_t& d = disparity[row + static_cast<size_t>(x)];
                if (mask != nullptr && mask[x] == 0) {
                    if (isTextured(left, stride, w, h, x, y, settings.textured_min_range))
                        state = edge(x);
                    continue;
                }
                const bool textured =
                    isTextured(left, stride, w, h, x, y, settings.textured_min_range);
                if (textured) {
                    state = edge(x);
                    continue;
                }
                const uint8_t before = edge_state[static_cast<size_t>(x)];
                if (d != kNoDisparity && before != 1 && state != 1 && (before == 3 || state == 3)) {
                    d = kNoDisparity;
                    range_limit[row + static_cast<size_t>(x)] = 1;
                }
            }
        }
    }

    // Hamming distance of the census of left pixel (x, y) and right pixel (xr, y).
    int censusCost(int x, int xr, int y)
    {
        int cost = 0;
        for (int p = 0; p < planes; ++p)
            cost += kBitsOfByte[planeRow(census_left, p, y)[x] ^ planeRow(census_right, p, y)[xr]];
        return cost;
    }

    // A table rather than std::popcount, which the baseline x86-64 target turns into a
    // library call.
    static constexpr std::array<uint8_t, 256> kBitsOfByte = [] {
        std::array<uint8_t, 256> bits{};
        for (int i = 0; i < 256; ++i)
            bits[static_cast<size_t>(i)] =
                static_cast<uint8_t>(std::popcount(static_cast<unsigned>(i)));
        return bits;
    }();

    void finishRows(const std::vector<int16_t>& source, int y0, int y1, const CensusSgmOutput& out)
    {
        const size_t w = static_cast<size_t>(settings.width);
        const size_t first = static_cast<size_t>(y0) * w, end = static_cast<size_t>(y1) * w;
        finishPixels(source.data() + first, end - first, out.disparity_px + first,
                     out.confidence + first);
    }

    // Every output written whatever the pixel, the choice made on bits (the compiler keeps
    // a branch for a choice between floats), and the arrays declared apart (a byte store
    // may otherwise alias anything): a vector loop.
    static void finishPixels(const int16_t* __restrict fixed_point, size_t count,
                             float* __restrict disparity, uint8_t* __restrict confidence)
    {
        constexpr uint32_t kNoneBits = 0x7f800000u; // +inf
        static_assert(std::bit_cast<float>(kNoneBits) == std::numeric_limits<float>::infinity());
        for (size_t i = 0; i < count; ++i) {
            const uint32_t none = fixed_point[i] == kNoDisparity ? ~0u : 0u;
            const auto value =
                std::bit_cast<uint32_t>(static_cast<float>(fixed_point[i]) * (1.0f / kSubpixel));
            disparity[i] = std::bit_cast<float>((value & ~none) | (kNoneBits & none));
            confidence[i] = static_cast<uint8_t>(confidence[i] & ~none);
        }
    }

    CensusSgmSettings settings;
    const SgmKernels* kernels;
    int lanes;
    int planes;
    int rx, ry;
    size_t padded_stride;
    uint8_t p2_by_step[256] = {};
    bool short_steps = false; // p2_by_step is constant from kPenaltySteps - 1 on
    DecideSettings decide;
    std::vector<uint8_t> padded_left, padded_right;
    size_t plane_margin = 0, plane_stride = 0;
    std::vector<uint8_t> census_left, census_right; // planes x (margin, height x width, margin)
    std::vector<uint8_t> census_right_reversed;     // each row backwards
    std::vector<int16_t> fixed, filtered;           // 16 x disparity, kNoDisparity = none
    std::vector<uint8_t> periodic_raw, periodic;    // periodic_pattern.hpp, width x height
    std::vector<BandScratch> bands;
    std::unique_ptr<BandPool> own_pool; // null when the pool is shared
    BandPool& pool;
    SpeckleFilter speckle;
};

CensusSgm::CensusSgm(const CensusSgmSettings& settings, BandPool* pool)
{
    validateCensusSgmSettings(settings);
    if (pool != nullptr && pool->threads() < settings.threads)
        throw std::invalid_argument("CensusSgm: a shared pool of " +
                                    std::to_string(pool->threads()) + " threads for " +
                                    std::to_string(settings.threads) + " bands");
    impl_ = std::make_unique<Impl>(settings, pool);
}

CensusSgm::~CensusSgm() = default;

void CensusSgm::compute(const uint8_t* left, size_t left_stride, const uint8_t* right,
                        size_t right_stride, const CensusSgmOutput& out, const LaneSpan* spans)
{
    Impl& m = *impl_;
    const CensusSgmSettings& s = m.settings;
    const int bands = s.threads;
    const int padded_rows = s.height + 2 * m.ry;

    m.pool.run(bands, [&](int band) {
        const int y0 = padded_rows * band / bands;
        const int y1 = padded_rows * (band + 1) / bands;
        m.pad(left, left_stride, m.padded_left, y0, y1);
        m.pad(right, right_stride, m.padded_right, y0, y1);
    });
    m.pool.run(bands, [&](int band) {
        const int y0 = s.height * band / bands;
        const int y1 = s.height * (band + 1) / bands;
        m.censusRows(m.padded_left, m.census_left, y0, y1);
        m.censusRows(m.padded_right, m.census_right, y0, y1);
        m.reverseRightRows(y0, y1);
        if (s.periodic_patterns)
            markPeriodicRows(left, left_stride, s.width, y0, y1, s.census_width,
                             s.num_disparities + std::abs(s.min_disparity),
                             m.bands[static_cast<size_t>(band)].edges.data(),
                             m.periodic_raw.data());
    });
    if (s.periodic_patterns)
        m.pool.run(bands, [&](int band) {
            spreadPeriodicRows(m.periodic_raw.data(), s.width, s.height, s.height * band / bands,
                               s.height * (band + 1) / bands, m.periodic.data());
        });
    m.pool.run(bands, [&](int band) { m.matchBand(band, left, left_stride, spans, out); });

    const auto band_start = [&](int band) { return s.height * band / bands; };
    std::vector<int16_t>* result = s.median ? &m.filtered : &m.fixed;
    const int max_step = s.speckle_range_px * kSubpixel;
    // The median reads the rows around its band, which the other bands have finished;
    // the speckle labels only the band's own rows.
    const bool checks_texture = s.textured_max_cost >= 0 || s.periodic_patterns;
    m.pool.run(bands, [&](int band) {
        if (s.median)
            m.medianRows(band_start(band), band_start(band + 1));
        // Before the speckle removal, which then takes what is left of a surface that the
        // check emptied.
        if (checks_texture) {
            m.dropUnmatchedTexture(*result, left, left_stride, band_start(band),
                                   band_start(band + 1), nullptr, out.range_limit);
            m.dropFlatBetweenUnmatchedEdges(
                *result, left, left_stride, band_start(band), band_start(band + 1),
                m.bands[static_cast<size_t>(band)].edge_state.data(), out.range_limit);
        }
        if (s.speckle_window_px > 0)
            m.speckle.labelBand(result->data(), kNoDisparity, max_step, band_start(band),
                                band_start(band + 1));
    });
    if (s.speckle_window_px > 0) {
        int starts[64]; // threads <= 64 (validated)
        for (int band = 0; band < bands; ++band)
            starts[band] = band_start(band);
        m.speckle.joinBands(result->data(), max_step, starts, bands);
    }
    // The gaps run along columns too, across the bands: bridged between the speckle
    // removal and the last pass, on this thread.
    const bool bridges = s.gap_fill_px > 0 || s.periodic_patterns;
    m.pool.run(bands, [&](int band) {
        if (s.speckle_window_px > 0)
            m.speckle.removeBand(result->data(), kNoDisparity, s.speckle_window_px,
                                 band_start(band), band_start(band + 1));
        if (!bridges)
            m.finishRows(*result, band_start(band), band_start(band + 1), out);
    });
    if (!bridges)
        return;
    if (s.gap_fill_px > 0)
        bridgeGaps(result->data(), out.confidence, out.range_limit, s.width, s.height,
                   s.gap_fill_px);
    else
        bridgeGaps(result->data(), out.confidence, out.range_limit, s.width, s.height,
                   s.periodic_gap_fill_px, m.periodic.data());
    m.pool.run(bands, [&](int band) {
        if (checks_texture)
            m.dropUnmatchedTexture(*result, left, left_stride, band_start(band),
                                   band_start(band + 1), out.confidence, nullptr);
        m.finishRows(*result, band_start(band), band_start(band + 1), out);
    });
}

const CensusSgmSettings& CensusSgm::settings() const
{
    return impl_->settings;
}

void CensusSgm::censusRows(int y, CensusRowPointers& out) const
{
    Impl& m = *impl_;
    for (int p = 0; p < m.planes; ++p) {
        out.left[p] = m.planeRow(m.census_left, p, y);
        out.right[p] = m.planeRow(m.census_right, p, y);
        out.right_reversed[p] = m.planeRow(m.census_right_reversed, p, y);
    }
    out.rows = CensusRows{out.left, out.right, out.right_reversed, m.planes};
}

const SgmKernels& CensusSgm::kernels() const
{
    return *impl_->kernels;
}

const char* CensusSgm::target() const
{
    return impl_->kernels->target;
}

} // namespace stereod::sgm
