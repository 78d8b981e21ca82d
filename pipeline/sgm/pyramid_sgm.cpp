#include "pipeline/sgm/pyramid_sgm.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "base/settings_error.hpp"
#include "pipeline/sgm/band_pool.hpp"
#include "pipeline/sgm/guided_spans.hpp"
#include "pipeline/sgm/texture.hpp"

namespace stereod::sgm {
namespace {

using Clock = std::chrono::steady_clock;

// +inf: no disparity. Nothing measured is below it.
constexpr float kNone = std::numeric_limits<float>::infinity();

// Full-resolution pixels mergeRows() skips together when nothing in them needs merging.
constexpr int kMergeChunk = 32;

double msBetween(Clock::time_point a, Clock::time_point b)
{
    return std::chrono::duration<double, std::milli>(b - a).count();
}

// Floor division: -3 / 2 = -2, so that the coarse range starts at or before the full one.
int halfFloor(int value)
{
    return value >= 0 ? value / 2 : -((-value + 1) / 2);
}

// 2x2 means, rounded: rows y0..y1-1 of the coarse level's image (half_width wide,
// contiguous).
void halveRows(const uint8_t* image, size_t stride, int half_width, int y0, int y1, uint8_t* half)
{
    for (int y = y0; y < y1; ++y) {
        const uint8_t* a = image + static_cast<size_t>(2 * y) * stride;
        const uint8_t* b = a + stride;
        uint8_t* out = half + static_cast<size_t>(y) * static_cast<size_t>(half_width);
        for (int x = 0; x < half_width; ++x)
            out[x] =
                static_cast<uint8_t>((a[2 * x] + a[2 * x + 1] + b[2 * x] + b[2 * x + 1] + 2) >> 2);
    }
}

bool hasCoarseLevel(const PyramidSgmSettings& s)
{
    return s.extended_range;
}

bool isGuided(const PyramidSgmSettings& s)
{
    return s.extended_range && s.guided_search;
}

} // namespace

CensusSgmSettings coarseLevelSettings(const CensusSgmSettings& full)
{
    // The natural scenes' tuning whatever the full level's: it declines an ambiguous
    // match rather than resolve it from a pattern's ends, and what the coarse level
    // reports beyond the full range is taken as measured.
    CensusSgmSettings c;
    c.width = full.width / 2;
    c.height = full.height / 2;
    c.min_disparity = halfFloor(full.min_disparity);
    c.num_disparities = full.num_disparities;
    c.census_width = full.census_width;
    c.census_height = full.census_height;
    c.paths = full.paths;
    c.p1 = full.p1;
    c.p2 = full.p2;
    c.lr_max_diff_px = full.lr_max_diff_px;
    c.edge_margin_px = full.edge_margin_px;
    c.speckle_window_px = CensusSgmSettings{}.speckle_window_px / 4;
    c.threads = full.threads;
    c.use_simd = full.use_simd;
    return c;
}

void validatePyramidSgmSettings(const PyramidSgmSettings& s)
{
    validateCensusSgmSettings(s.full);
    if (!(s.guided_max_share >= 0.0 && s.guided_max_share <= 1.0))
        throw SettingsError("guided_max_share", "must be a share within 0..1, got " +
                                                    std::to_string(s.guided_max_share));
    if (hasCoarseLevel(s)) {
        const CensusSgmSettings coarse = coarseLevelSettings(s.full);
        const bool sized = s.full.width != 0 || s.full.height != 0;
        if (sized &&
            (coarse.width <= coarse.census_width / 2 || coarse.height <= coarse.census_height / 2))
            throw SettingsError("extended_range",
                                "a " + std::to_string(s.full.width) + "x" +
                                    std::to_string(s.full.height) +
                                    " image is too small for a half-resolution level; turn "
                                    "the extended range off");
        if (sized)
            validateCensusSgmSettings(coarse);
    }
}

size_t pyramidSgmMemoryBytes(const PyramidSgmSettings& s)
{
    size_t bytes = censusSgmMemoryBytes(s.full);
    if (hasCoarseLevel(s)) {
        const CensusSgmSettings coarse = coarseLevelSettings(s.full);
        const size_t area = static_cast<size_t>(coarse.width) * static_cast<size_t>(coarse.height);
        bytes += censusSgmMemoryBytes(coarse) + area * (2 + sizeof(float) + 4) +
                 3 * static_cast<size_t>(coarse.width) * static_cast<size_t>(s.full.threads);
        if (isGuided(s))
            bytes += GuidedSpans::memoryBytes(s.full, coarse);
    }
    if (s.near_field_probe) {
        const int width = hasCoarseLevel(s) ? s.full.width / 2 : s.full.width;
        bytes += static_cast<size_t>(width + 2 * kLaneAlign) * sizeof(uint16_t);
    }
    return bytes;
}

struct PyramidSgm::Impl {
    explicit Impl(const PyramidSgmSettings& s)
        : settings(s), pool(s.full.threads), full(s.full, &pool),
          full_last(s.full.min_disparity + s.full.num_disparities - 1)
    {
        extended_last = full_last;
        int probe_width = s.full.width, probe_height = s.full.height;
        if (hasCoarseLevel(s)) {
            const CensusSgmSettings c = coarseLevelSettings(s.full);
            coarse = std::make_unique<CensusSgm>(c, &pool);
            const size_t area = static_cast<size_t>(c.width) * static_cast<size_t>(c.height);
            half_left.assign(area, 0);
            half_right.assign(area, 0);
            coarse_disparity.assign(area, 0.0f);
            coarse_confidence.assign(area, 0);
            coarse_limit.assign(area, 0);
            coarse_near.assign(area, 0);
            coarse_given.assign(area, 0);
            texture_rows.assign(
                3 * static_cast<size_t>(c.width) * static_cast<size_t>(s.full.threads), 0);
            extended_last = 2 * (c.min_disparity + c.num_disparities - 1);
            probe_width = c.width;
            probe_height = c.height;
            if (isGuided(s))
                guide = std::make_unique<GuidedSpans>(s.full, c);
        }
        if (s.near_field_probe)
            probe = std::make_unique<NearFieldProbe>(probe_width, probe_height,
                                                     NearFieldProbeSettings{}, s.full.threads);
    }

    // Rows y0..y1-1 of the coarse level's result folded into the full level's (see the
    // header). Reads coarse_near around each row: classifyCoarseRows() must have finished
    // every coarse row.
    void mergeRows(int y0, int y1, const PyramidSgmOutput& out)
    {
        const int w = settings.full.width;
        const int cw = coarse->settings().width, ch = coarse->settings().height;
        for (int y = y0; y < y1; ++y) {
            const int cy = std::min(y / 2, ch - 1);
            const size_t row = static_cast<size_t>(y) * static_cast<size_t>(w);
            const size_t crow = static_cast<size_t>(cy) * static_cast<size_t>(cw);
            if (guided_now)
                dropDisagreeingRow(row, crow, out);
            for (int x0 = 0; x0 < w; x0 += kMergeChunk) {
                // Most of an image is neither near evidence of either level nor a near
                // surface of the coarse one: a chunk with none of them keeps what the
                // full level found, as it is.
                const bool whole = x0 + kMergeChunk <= 2 * cw;
                const size_t c = crow + static_cast<size_t>(x0 / 2);
                if (whole && quietChunk(coarse_near.data() + c, coarse_limit.data() + c,
                                        out.near_field + row + static_cast<size_t>(x0)))
                    continue;
                for (int x = x0; x < std::min(w, x0 + kMergeChunk); ++x)
                    mergePixel(x, cy, row + static_cast<size_t>(x), out);
            }
        }
    }

    // With the guided search, before the rest of the merge: a narrowly searched pixel has
    // no competitor outside its span to be told apart from, so the coarse level's match
    // over the whole range at the same place must agree with its disparity (an unmeasured
    // one does not). Not where the coarse level saw something nearer than its own range,
    // which mergePixel() marks whatever the full level found. Full-resolution row at
    // `row`, its coarse row at `crow`; one pass over the row, no per-pixel merge.
    void dropDisagreeingRow(size_t row, size_t crow, const PyramidSgmOutput& out)
    {
        const int w = settings.full.width;
        const int cw = coarse->settings().width;
        const float* coarse_row = coarse_disparity.data() + crow;
        const uint8_t* limit_row = coarse_limit.data() + crow;
        float* disparity = out.disparity_px + row;
        uint8_t* confidence = out.confidence + row;
        for (int x = 0; x < w; ++x) {
            const int cx = std::min(x / 2, cw - 1);
            const float fine = disparity[x];
            const bool agrees =
                std::abs(2.0f * coarse_row[cx] - fine) <= static_cast<float>(kGuideAgreePx);
            const bool drop = guide->narrow(row + static_cast<size_t>(x)) & (limit_row[cx] == 0) &
                              (fine < kNone) & !agrees;
            disparity[x] = drop ? kNone : fine;
            confidence[x] = drop ? uint8_t{0} : confidence[x];
        }
    }

    // Whether the kMergeChunk pixels from `near_field` on, over the kMergeChunk / 2 coarse
    // pixels from `near` and `limit` on, are left as they are by mergePixel(). Fixed
    // lengths and no branch: vector loops.
    static bool quietChunk(const uint8_t* near, const uint8_t* limit, const uint8_t* near_field)
    {
        uint8_t any = 0;
        for (int c = 0; c < kMergeChunk / 2; ++c)
            any |= static_cast<uint8_t>(near[c] | limit[c]);
        for (int x = 0; x < kMergeChunk; ++x)
            any |= static_cast<uint8_t>(near_field[x] == kNearerThanRange);
        return any == 0;
    }

    // Full-resolution pixel x of the row whose coarse row is cy, at index i.
    void mergePixel(int x, int cy, size_t i, const PyramidSgmOutput& out)
    {
        const int cw = coarse->settings().width;
        const int cx = std::min(x / 2, cw - 1);
        const size_t c =
            static_cast<size_t>(cy) * static_cast<size_t>(cw) + static_cast<size_t>(cx);
        if (coarse_limit[c] != 0) {
            out.near_field[i] = kNearerThanExtendedRange;
            return;
        }
        if (coarse_near[c] == 0) {
            // The full range's near end, next to a near surface the coarse level measured:
            // at least as near as that surface, the nearest around.
            if (out.near_field[i] == kNearerThanRange) {
                const float around = nearestSurfaceAround(cx, cy);
                if (around > 0.0f) {
                    out.near_field[i] = kNoNearEvidence;
                    out.disparity_px[i] = around;
                    out.confidence[i] = kExplainedConfidence;
                }
            }
            return;
        }
        const float coarse_px = 2.0f * coarse_disparity[c];
        const float fine = out.disparity_px[i];
        out.near_field[i] = kNoNearEvidence;
        if (std::isfinite(fine) && std::abs(fine - coarse_px) <= static_cast<float>(kMergeMarginPx))
            return; // the full level agrees, to a finer pixel
        out.disparity_px[i] = coarse_px;
        out.confidence[i] = static_cast<uint8_t>(std::max(2, coarse_confidence[c] / 2));
    }

    // Rows y0..y1-1 of PyramidSgmOutput::coarse_only_px, after mergeRows() of the same rows,
    // in `region` (clipped to the image) alone: only the reading counts them.
    void writeCoarseOnlyRows(int y0, int y1, PixelRect region, const PyramidSgmOutput& out) const
    {
        const int w = settings.full.width;
        const CensusSgmSettings& c = coarse->settings();
        for (int y = std::max(y0, region.y); y < std::min(y1, region.y + region.height); ++y) {
            const size_t crow =
                static_cast<size_t>(std::min(y / 2, c.height - 1)) * static_cast<size_t>(c.width);
            const size_t row = static_cast<size_t>(y) * static_cast<size_t>(w);
            const float* fine = out.disparity_px + row;
            float* only = out.coarse_only_px + row;
            for (int x = region.x; x < region.x + region.width; ++x) {
                const size_t ci = crow + static_cast<size_t>(std::min(x / 2, c.width - 1));
                const float offered = coarse_given[ci] != 0 ? 2.0f * coarse_disparity[ci] : kNone;
                only[x] = fine[x] < kNone ? kNone : offered;
            }
        }
    }

    // Coarse rows y0..y1-1, once per coarse pixel rather than once for each of the four
    // it covers, one texture test for both:
    //  - coarse_near: a surface measured at or beyond the near end of the full range
    //    (within kMergeMarginPx of it), on texture: a flat patch matches any flat patch,
    //    and says nothing about nearness;
    //  - coarse_given: a match on texture that coarse_only_px may give.
    void classifyCoarseRows(int band, int y0, int y1)
    {
        const CensusSgmSettings& c = coarse->settings();
        const float full_edge = static_cast<float>(full_last - kMergeMarginPx);
        const size_t cw = static_cast<size_t>(c.width);
        uint8_t* column_lo = texture_rows.data() + 3 * cw * static_cast<size_t>(band);
        uint8_t* column_hi = column_lo + cw;
        uint8_t* textured = column_hi + cw;
        for (int y = y0; y < y1; ++y) {
            texturedRow(half_left.data(), cw, c.width, c.height, y, c.textured_min_range, column_lo,
                        column_hi, textured);
            // No branch: a vector loop.
            const size_t row = static_cast<size_t>(y) * cw;
            const float* disparity = coarse_disparity.data() + row;
            const uint8_t* limit = coarse_limit.data() + row;
            uint8_t* near = coarse_near.data() + row;
            uint8_t* given = coarse_given.data() + row;
            for (size_t x = 0; x < cw; ++x) {
                const float coarse_px = 2.0f * disparity[x];
                const bool on_texture = (coarse_px < kNone) & (textured[x] != 0);
                near[x] = on_texture & (coarse_px >= full_edge);
                given[x] = on_texture & (limit[x] == 0);
            }
        }
    }

    // The largest disparity (full-resolution pixels) of the near surfaces the coarse level
    // measured within kExplainRadius of (cx, cy); 0 when there is none.
    float nearestSurfaceAround(int cx, int cy) const
    {
        const CensusSgmSettings& c = coarse->settings();
        float nearest = 0.0f;
        for (int y = std::max(0, cy - kExplainRadius);
             y <= std::min(c.height - 1, cy + kExplainRadius); ++y)
            for (int x = std::max(0, cx - kExplainRadius);
                 x <= std::min(c.width - 1, cx + kExplainRadius); ++x) {
                const size_t i =
                    static_cast<size_t>(y) * static_cast<size_t>(c.width) + static_cast<size_t>(x);
                if (coarse_near[i] != 0)
                    nearest = std::max(nearest, 2.0f * coarse_disparity[i]);
            }
        return nearest;
    }

    // The probe over the region, at the level the widest range was searched at.
    void runProbe(const uint8_t* left, size_t left_stride, PixelRect region,
                  const PyramidSgmOutput& out)
    {
        if (!probe || region.width <= 0 || region.height <= 0)
            return;
        const bool at_coarse = coarse != nullptr;
        const int scale = at_coarse ? 2 : 1;
        const CensusSgm& level = at_coarse ? *coarse : full;
        const CensusSgmSettings& ls = level.settings();
        const PixelRect scaled{region.x / scale, region.y / scale,
                               (region.x + region.width + scale - 1) / scale - region.x / scale,
                               (region.y + region.height + scale - 1) / scale - region.y / scale};
        if (at_coarse)
            probe->run(half_left.data(), static_cast<size_t>(ls.width), level, scaled,
                       ls.min_disparity, ls.min_disparity + ls.num_disparities - 1, &pool);
        else
            probe->run(left, left_stride, level, scaled, ls.min_disparity,
                       ls.min_disparity + ls.num_disparities - 1, &pool);
        const uint8_t mark = at_coarse ? kNearerThanExtendedRange : kNearerThanRange;
        const int w = settings.full.width, h = settings.full.height;
        for (const PixelRect& tile : probe->evidenceTiles()) {
            const int x0 = tile.x * scale, x1 = std::min(w, (tile.x + tile.width) * scale);
            const int y0 = tile.y * scale, y1 = std::min(h, (tile.y + tile.height) * scale);
            for (int y = y0; y < y1; ++y)
                std::fill(out.near_field + static_cast<size_t>(y) * static_cast<size_t>(w) + x0,
                          out.near_field + static_cast<size_t>(y) * static_cast<size_t>(w) + x1,
                          mark);
        }
    }

    PyramidSgmSettings settings;
    // Every band of the pyramid's work (both levels' matches, halving, merging, the probe)
    // over settings.full.threads: one set of threads, warm from one part to the next.
    BandPool pool;
    CensusSgm full;
    int full_last;
    int extended_last = 0;
    std::unique_ptr<CensusSgm> coarse;  // null without the extended range
    std::unique_ptr<GuidedSpans> guide; // null without the guided search
    bool guided_now = false;            // the last compute()'s full level took guide's spans
    std::vector<uint8_t> half_left, half_right;
    std::vector<float> coarse_disparity;
    std::vector<uint8_t> coarse_confidence, coarse_limit;
    std::vector<uint8_t> coarse_near, coarse_given; // classifyCoarseRows()
    std::vector<uint8_t> texture_rows;              // its texturedRow() scratch, per band
    std::unique_ptr<NearFieldProbe> probe;
    PyramidSgmTimings timings;
};

PyramidSgm::PyramidSgm(const PyramidSgmSettings& settings)
{
    validatePyramidSgmSettings(settings);
    impl_ = std::make_unique<Impl>(settings);
}

PyramidSgm::~PyramidSgm() = default;

void PyramidSgm::compute(const uint8_t* left, size_t left_stride, const uint8_t* right,
                         size_t right_stride, PixelRect probe_region, const PyramidSgmOutput& out)
{
    Impl& m = *impl_;
    const int bands = m.settings.full.threads;
    const Clock::time_point t0 = Clock::now();
    if (m.coarse) {
        const CensusSgmSettings& c = m.coarse->settings();
        m.pool.run(bands, [&](int band) {
            const int y0 = c.height * band / bands, y1 = c.height * (band + 1) / bands;
            halveRows(left, left_stride, c.width, y0, y1, m.half_left.data());
            halveRows(right, right_stride, c.width, y0, y1, m.half_right.data());
        });
        m.coarse->compute(
            m.half_left.data(), static_cast<size_t>(c.width), m.half_right.data(),
            static_cast<size_t>(c.width),
            {m.coarse_disparity.data(), m.coarse_confidence.data(), m.coarse_limit.data()});
        if (m.guide) {
            m.guide->predict(m.coarse_disparity.data(), m.coarse_limit.data(), &m.pool);
            m.guided_now = m.guide->searchedShare() <= m.settings.guided_max_share;
        }
    }
    const Clock::time_point t1 = Clock::now();
    m.full.compute(left, left_stride, right, right_stride,
                   {out.disparity_px, out.confidence, out.near_field},
                   m.guided_now ? m.guide->spans() : nullptr);
    const Clock::time_point t2 = Clock::now();
    if (m.coarse) {
        const int ch = m.coarse->settings().height, h = m.settings.full.height;
        const PixelRect region = clippedTo(probe_region, m.settings.full.width, h);
        m.pool.run(bands, [&](int band) {
            m.classifyCoarseRows(band, ch * band / bands, ch * (band + 1) / bands);
        });
        m.pool.run(bands, [&](int band) {
            const int y0 = h * band / bands, y1 = h * (band + 1) / bands;
            m.mergeRows(y0, y1, out);
            if (out.coarse_only_px != nullptr)
                m.writeCoarseOnlyRows(y0, y1, region, out);
        });
    }
    const Clock::time_point t3 = Clock::now();
    m.runProbe(left, left_stride, probe_region, out);
    // The frame's matching is done: what follows (depth, the reading, the cloud) runs on
    // other threads, which the band threads' spinning would take cores from.
    m.pool.rest();
    m.timings = {msBetween(t1, t2), msBetween(t0, t1) + msBetween(t2, t3),
                 msBetween(t3, Clock::now())};
}

const PyramidSgmTimings& PyramidSgm::timings() const
{
    return impl_->timings;
}

double PyramidSgm::searchedShare() const
{
    return impl_->guided_now ? impl_->guide->searchedShare() : 1.0;
}

const PyramidSgmSettings& PyramidSgm::settings() const
{
    return impl_->settings;
}

int PyramidSgm::fullRangeLast() const
{
    return impl_->full_last;
}

int PyramidSgm::extendedRangeLast() const
{
    return impl_->extended_last;
}

int PyramidSgm::nearEvidenceTiles() const
{
    return impl_->probe ? static_cast<int>(impl_->probe->evidenceTiles().size()) : 0;
}

int PyramidSgm::probedTiles() const
{
    return impl_->probe ? impl_->probe->probedTiles() : 0;
}

const char* PyramidSgm::target() const
{
    return impl_->full.target();
}

} // namespace stereod::sgm
