#include "pipeline/sgm/near_field_probe.hpp"

#include <algorithm>
#include <bit>
#include <cstdlib>
#include <limits>

#include "pipeline/sgm/texture.hpp"

namespace stereod::sgm {

NearFieldProbe::NearFieldProbe(int width, int height, const NearFieldProbeSettings& settings)
    : width_(width), height_(height), settings_(settings)
{
    // A curve holds at most one entry per column, rounded up for the kernels.
    curve_.assign(static_cast<size_t>(width + 2 * kLaneAlign), 0);
    const int tiles_x = (width + settings.tile_px - 1) / settings.tile_px;
    const int tiles_y = (height + settings.tile_px - 1) / settings.tile_px;
    tiles_.resize(static_cast<size_t>(tiles_x) * static_cast<size_t>(tiles_y));
    evidence_.reserve(tiles_.size());
    const size_t tile_area = static_cast<size_t>(settings.tile_px) * settings.tile_px;
    sample_x_.reserve(tile_area);
    sample_y_.reserve(tile_area);
}

// Whether a census tells matches apart: a pixel on the dark side of an edge has almost no
// darker neighbour, its census almost no bit set, and it matches any dark or uniform
// patch (a rectified image's black border, say) as well as its true match.
bool NearFieldProbe::informative(const CensusRows& rows, int x, int bits)
{
    int set = 0;
    for (int p = 0; p < rows.planes; ++p)
        set += std::popcount(static_cast<unsigned>(rows.left[p][x]));
    return set >= bits / 8 && set <= bits - bits / 8;
}

// Whether the tile's samples differ from one another: one straight edge through a tile
// gives every sample nearly the same census, and it matches any parallel edge of the same
// polarity, in the range or beyond it, as well as its true match.
bool NearFieldProbe::diverse(const CensusSgm& census, int step) const
{
    const size_t n = sample_x_.size();
    CensusRowPointers a, b;
    long distance = 0, pairs = 0;
    for (size_t i = 0; i < n; i += static_cast<size_t>(step)) {
        census.censusRows(sample_y_[i], a);
        for (size_t j = i + static_cast<size_t>(step); j < n; j += static_cast<size_t>(step)) {
            census.censusRows(sample_y_[j], b);
            for (int p = 0; p < a.rows.planes; ++p)
                distance += std::popcount(
                    static_cast<unsigned>(a.left[p][sample_x_[i]] ^ b.left[p][sample_x_[j]]));
            ++pairs;
        }
    }
    const int bits = census.settings().census_width * census.settings().census_height - 1;
    return pairs > 0 && distance >= pairs * (bits * settings_.diversity_percent / 100);
}

void NearFieldProbe::run(const uint8_t* left, size_t stride, const CensusSgm& census,
                         PixelRect region, int first, int last)
{
    evidence_.clear();
    probed_ = 0;
    const int x_begin = std::clamp(region.x, 0, width_);
    const int y_begin = std::clamp(region.y, 0, height_);
    const int x_end = std::clamp(region.x + region.width, x_begin, width_);
    const int y_end = std::clamp(region.y + region.height, y_begin, height_);
    const int t = settings_.tile_px;
    const int tiles_x = (x_end - x_begin + t - 1) / t;
    const int tiles_y = (y_end - y_begin + t - 1) / t;
    const int span = last - first + 1;
    const int beyond_last = last + settings_.beyond_spans * span;
    const SgmKernels& kernels = census.kernels();
    const int bits = census.settings().census_width * census.settings().census_height - 1;
    CensusRowPointers rows;

    for (int ty = 0; ty < tiles_y; ++ty)
        for (int tx = 0; tx < tiles_x; ++tx) {
            Tile& tile = tiles_[static_cast<size_t>(ty) * static_cast<size_t>(tiles_x) +
                                static_cast<size_t>(tx)];
            tile = Tile{};
            const int x0 = x_begin + tx * t, y0 = y_begin + ty * t;
            const int x1 = std::min(x0 + t, x_end), y1 = std::min(y0 + t, y_end);
            sample_x_.clear();
            sample_y_.clear();
            for (int y = y0; y < y1; ++y) {
                census.censusRows(y, rows);
                for (int x = x0; x < x1; ++x)
                    if (isTextured(left, stride, width_, height_, x, y,
                                   settings_.texture_min_range) &&
                        informative(rows.rows, x, bits)) {
                        sample_x_.push_back(x);
                        sample_y_.push_back(y);
                    }
            }
            const int found = static_cast<int>(sample_x_.size());
            if (found < settings_.min_textured)
                continue;
            // Every pixel's right match must stay inside the row: the disparities a tile
            // can be matched at end at its leftmost sample.
            int leftmost = x1, rightmost = x0;
            const int step = std::max(1, found / settings_.samples_per_tile);
            for (int i = 0; i < found; i += step) {
                leftmost = std::min(leftmost, sample_x_[static_cast<size_t>(i)]);
                rightmost = std::max(rightmost, sample_x_[static_cast<size_t>(i)]);
            }
            if (!diverse(census, step))
                continue;
            // Right pixels whose census window reaches past the image's left edge are left
            // out: the edge's padding (or a rectified image's black border) matches any dark
            // pixel.
            const int top = std::min(leftmost - census.settings().census_width, beyond_last);
            const int lowest = std::max(first, rightmost - (width_ - 1));
            if (top <= last || lowest > last)
                continue; // nothing beyond the range, or nothing in it, to compare
            const int count = top - lowest + 1;
            std::fill(curve_.begin(), curve_.begin() + count + kLaneAlign, uint16_t{0});
            for (int i = 0; i < found; i += step) {
                const int x = sample_x_[static_cast<size_t>(i)];
                census.censusRows(sample_y_[static_cast<size_t>(i)], rows);
                kernels.cost_curve(rows.rows, x, width_, lowest, count, curve_.data());
            }
            ++probed_;
            const int in_count = last - lowest + 1;
            const uint16_t best_in = *std::min_element(curve_.begin(), curve_.begin() + in_count);
            const auto beyond = std::min_element(curve_.begin() + in_count, curve_.begin() + count);
            const int samples = (found + step - 1) / step;
            tile.passed =
                static_cast<int>(*beyond) * 100 <
                    static_cast<int>(best_in) * (100 - settings_.margin_percent) &&
                static_cast<int>(*beyond) * 100 <= samples * bits * settings_.good_match_percent;
            tile.beyond_disparity = lowest + static_cast<int>(beyond - curve_.begin());
        }

    // Evidence: a tile that passed beside one that passed at about the same disparity.
    const auto agrees = [&](const Tile& tile, int tx, int ty) {
        if (tx < 0 || ty < 0 || tx >= tiles_x || ty >= tiles_y)
            return false;
        const Tile& other = tiles_[static_cast<size_t>(ty) * static_cast<size_t>(tiles_x) +
                                   static_cast<size_t>(tx)];
        return other.passed &&
               std::abs(other.beyond_disparity - tile.beyond_disparity) <= settings_.agree_px;
    };
    for (int ty = 0; ty < tiles_y; ++ty)
        for (int tx = 0; tx < tiles_x; ++tx) {
            const Tile& tile = tiles_[static_cast<size_t>(ty) * static_cast<size_t>(tiles_x) +
                                      static_cast<size_t>(tx)];
            if (!tile.passed)
                continue;
            if (agrees(tile, tx - 1, ty) || agrees(tile, tx + 1, ty) || agrees(tile, tx, ty - 1) ||
                agrees(tile, tx, ty + 1)) {
                const int x0 = x_begin + tx * t, y0 = y_begin + ty * t;
                evidence_.push_back(
                    {x0, y0, std::min(x0 + t, x_end) - x0, std::min(y0 + t, y_end) - y0});
            }
        }
}

} // namespace stereod::sgm
