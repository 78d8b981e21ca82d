#include "pipeline/sgm/near_field_probe.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cstdlib>
#include <limits>

#include "pipeline/sgm/texture.hpp"

namespace stereod::sgm {
namespace {

// Bits set in each byte value. A census plane is a byte; x86-64's baseline has no popcnt
// instruction, and std::popcount there is a call into the runtime for every byte.
constexpr std::array<uint8_t, 256> kBitsOfByte = [] {
    std::array<uint8_t, 256> bits{};
    for (int v = 0; v < 256; ++v)
        bits[static_cast<size_t>(v)] =
            static_cast<uint8_t>(std::popcount(static_cast<unsigned>(v)));
    return bits;
}();

// The bits set in a word, in a few shifts and adds (for the same reason as the table).
int bitsSet(uint64_t v)
{
    v -= (v >> 1) & 0x5555555555555555ULL;
    v = (v & 0x3333333333333333ULL) + ((v >> 2) & 0x3333333333333333ULL);
    v = (v + (v >> 4)) & 0x0F0F0F0F0F0F0F0FULL;
    return static_cast<int>((v * 0x0101010101010101ULL) >> 56);
}

} // namespace

NearFieldProbe::NearFieldProbe(int width, int height, const NearFieldProbeSettings& settings,
                               int threads)
    : width_(width), height_(height), settings_(settings),
      scratch_(static_cast<size_t>(std::max(1, threads)))
{
    const int tiles_x = (width + settings.tile_px - 1) / settings.tile_px;
    const int tiles_y = (height + settings.tile_px - 1) / settings.tile_px;
    tiles_.resize(static_cast<size_t>(tiles_x) * static_cast<size_t>(tiles_y));
    evidence_.reserve(tiles_.size());
    const size_t tile_area = static_cast<size_t>(settings.tile_px) * settings.tile_px;
    for (Scratch& scratch : scratch_) {
        // A curve holds at most one entry per column, rounded up for the kernels.
        scratch.curve.assign(static_cast<size_t>(width + 2 * kLaneAlign), 0);
        scratch.sample_x.reserve(tile_area);
        scratch.sample_census.reserve(tile_area);
        scratch.sample_y.reserve(tile_area);
    }
}

// Whether a census tells matches apart: a pixel on the dark side of an edge has almost no
// darker neighbour, its census almost no bit set, and it matches any dark or uniform
// patch (a rectified image's black border, say) as well as its true match.
bool NearFieldProbe::informative(const CensusRows& rows, int x, int bits)
{
    int set = 0;
    for (int p = 0; p < rows.planes; ++p)
        set += kBitsOfByte[rows.left[p][x]];
    return set >= bits / 8 && set <= bits - bits / 8;
}

// Whether the tile's samples differ from one another: one straight edge through a tile
// gives every sample nearly the same census, and it matches any parallel edge of the same
// polarity, in the range or beyond it, as well as its true match.
bool NearFieldProbe::diverse(const CensusSgm& census, Scratch& scratch, int step) const
{
    // Each sample's census as one word (at most 64 bits), then the pairs' distances.
    std::vector<uint64_t>& words = scratch.sample_census;
    words.clear();
    CensusRowPointers rows;
    for (size_t i = 0; i < scratch.sample_x.size(); i += static_cast<size_t>(step)) {
        census.censusRows(scratch.sample_y[i], rows);
        uint64_t word = 0;
        for (int p = 0; p < rows.rows.planes; ++p)
            word |= static_cast<uint64_t>(rows.left[p][scratch.sample_x[i]]) << (8 * p);
        words.push_back(word);
    }
    long distance = 0, pairs = 0;
    for (size_t i = 0; i < words.size(); ++i)
        for (size_t j = i + 1; j < words.size(); ++j) {
            distance += bitsSet(words[i] ^ words[j]);
            ++pairs;
        }
    const int bits = census.settings().census_width * census.settings().census_height - 1;
    return pairs > 0 && distance >= pairs * (bits * settings_.diversity_percent / 100);
}

void NearFieldProbe::probeTileRows(const uint8_t* left, size_t stride, const CensusSgm& census,
                                   const Grid& grid, int ty0, int ty_step, Scratch& scratch)
{
    const int t = settings_.tile_px;
    const SgmKernels& kernels = census.kernels();
    std::vector<int>& sample_x = scratch.sample_x;
    std::vector<int>& sample_y = scratch.sample_y;
    std::vector<uint16_t>& curve = scratch.curve;
    CensusRowPointers rows;
    for (int ty = ty0; ty < grid.tiles_y; ty += ty_step)
        for (int tx = 0; tx < grid.tiles_x; ++tx) {
            Tile& tile = tiles_[static_cast<size_t>(ty) * static_cast<size_t>(grid.tiles_x) +
                                static_cast<size_t>(tx)];
            tile = Tile{};
            const int x0 = grid.x_begin + tx * t, y0 = grid.y_begin + ty * t;
            const int x1 = std::min(x0 + t, grid.x_end), y1 = std::min(y0 + t, grid.y_end);
            sample_x.clear();
            sample_y.clear();
            for (int y = y0; y < y1; ++y) {
                census.censusRows(y, rows);
                for (int x = x0; x < x1; ++x)
                    if (isTextured(left, stride, width_, height_, x, y,
                                   settings_.texture_min_range) &&
                        informative(rows.rows, x, grid.bits)) {
                        sample_x.push_back(x);
                        sample_y.push_back(y);
                    }
            }
            const int found = static_cast<int>(sample_x.size());
            if (found < settings_.min_textured)
                continue;
            // Every pixel's right match must stay inside the row: the disparities a tile
            // can be matched at end at its leftmost sample.
            int leftmost = x1, rightmost = x0;
            const int step = std::max(1, found / settings_.samples_per_tile);
            for (int i = 0; i < found; i += step) {
                leftmost = std::min(leftmost, sample_x[static_cast<size_t>(i)]);
                rightmost = std::max(rightmost, sample_x[static_cast<size_t>(i)]);
            }
            if (!diverse(census, scratch, step))
                continue;
            // Right pixels whose census window reaches past the image's left edge are left
            // out: the edge's padding (or a rectified image's black border) matches any dark
            // pixel.
            const int top = std::min(leftmost - census.settings().census_width, grid.beyond_last);
            const int lowest = std::max(grid.first, rightmost - (width_ - 1));
            if (top <= grid.last || lowest > grid.last)
                continue; // nothing beyond the range, or nothing in it, to compare
            const int count = top - lowest + 1;
            std::fill(curve.begin(), curve.begin() + count + kLaneAlign, uint16_t{0});
            for (int i = 0; i < found; i += step) {
                const int x = sample_x[static_cast<size_t>(i)];
                census.censusRows(sample_y[static_cast<size_t>(i)], rows);
                kernels.cost_curve(rows.rows, x, width_, lowest, count, curve.data());
            }
            ++scratch.probed;
            const int in_count = grid.last - lowest + 1;
            const uint16_t best_in = *std::min_element(curve.begin(), curve.begin() + in_count);
            const auto beyond = std::min_element(curve.begin() + in_count, curve.begin() + count);
            const int samples = (found + step - 1) / step;
            tile.passed = static_cast<int>(*beyond) * 100 <
                              static_cast<int>(best_in) * (100 - settings_.margin_percent) &&
                          static_cast<int>(*beyond) * 100 <=
                              samples * grid.bits * settings_.good_match_percent;
            tile.beyond_disparity = lowest + static_cast<int>(beyond - curve.begin());
        }
}

void NearFieldProbe::run(const uint8_t* left, size_t stride, const CensusSgm& census,
                         PixelRect region, int first, int last, BandPool* pool)
{
    evidence_.clear();
    Grid grid{};
    const PixelRect inside = clippedTo(region, width_, height_);
    grid.x_begin = inside.x;
    grid.y_begin = inside.y;
    grid.x_end = inside.x + inside.width;
    grid.y_end = inside.y + inside.height;
    const int t = settings_.tile_px;
    grid.tiles_x = (grid.x_end - grid.x_begin + t - 1) / t;
    grid.tiles_y = (grid.y_end - grid.y_begin + t - 1) / t;
    grid.first = first;
    grid.last = last;
    grid.beyond_last = last + settings_.beyond_spans * (last - first + 1);
    grid.bits = census.settings().census_width * census.settings().census_height - 1;
    for (Scratch& scratch : scratch_)
        scratch.probed = 0;

    const int bands =
        pool != nullptr ? std::min(static_cast<int>(scratch_.size()), grid.tiles_y) : 1;
    // Band k takes every bands-th row of tiles from row k: a region's texture, which sets a
    // tile's work, is rarely spread evenly from its top to its bottom.
    if (bands > 1)
        pool->run(bands, [&](int band) {
            probeTileRows(left, stride, census, grid, band, bands,
                          scratch_[static_cast<size_t>(band)]);
        });
    else
        probeTileRows(left, stride, census, grid, 0, 1, scratch_[0]);
    probed_ = 0;
    for (const Scratch& scratch : scratch_)
        probed_ += scratch.probed;

    // Evidence: a tile that passed beside one that passed at about the same disparity.
    const int tiles_x = grid.tiles_x, tiles_y = grid.tiles_y;
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
                const int x0 = grid.x_begin + tx * t, y0 = grid.y_begin + ty * t;
                evidence_.push_back(
                    {x0, y0, std::min(x0 + t, grid.x_end) - x0, std::min(y0 + t, grid.y_end) - y0});
            }
        }
}

} // namespace stereod::sgm
