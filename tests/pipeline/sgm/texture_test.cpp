// The texture test of a whole row (texturedRow) against the one of a pixel (isTextured),
// which the matcher's checks and the near-field probe use: the same answer at every pixel,
// at the image's edges and on images narrower or shorter than the 5x3 window.

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "pipeline/sgm/texture.hpp"
#include "tests/pipeline/sgm/synthetic_pair.hpp"

namespace stereod::sgm {
namespace {

// Flat patches of random grey levels with noise of random strength inside each: some
// flat, some textured, edges between them.
std::vector<uint8_t> patchwork(int width, int height, uint32_t seed)
{
    test::Random random(seed);
    std::vector<uint8_t> image(static_cast<size_t>(width) * static_cast<size_t>(height));
    for (int py = 0; py < height; py += 4)
        for (int px = 0; px < width; px += 6) {
            const int level = random.uniform(0, 255);
            const int noise = random.uniform(0, 3) == 0 ? random.uniform(0, 60) : 0;
            for (int y = py; y < std::min(height, py + 4); ++y)
                for (int x = px; x < std::min(width, px + 6); ++x)
                    image[static_cast<size_t>(y) * static_cast<size_t>(width) +
                          static_cast<size_t>(x)] =
                        static_cast<uint8_t>(std::clamp(level + random.uniform(0, noise), 0, 255));
        }
    return image;
}

TEST(TextureTest, ARowAtOnceIsEveryPixelsOwnTest)
{
    int textured_pixels = 0, flat_pixels = 0;
    for (const auto& [width, height] :
         {std::pair{97, 61}, std::pair{1, 5}, std::pair{4, 1}, std::pair{5, 3}, std::pair{2, 2}}) {
        const std::vector<uint8_t> image = patchwork(width, height, 7u + width);
        std::vector<uint8_t> lo(static_cast<size_t>(width)), hi(lo.size()), textured(lo.size());
        for (const int min_range : {1, 20, 60})
            for (int y = 0; y < height; ++y) {
                texturedRow(image.data(), static_cast<size_t>(width), width, height, y, min_range,
                            lo.data(), hi.data(), textured.data());
                for (int x = 0; x < width; ++x) {
                    const bool expected = isTextured(image.data(), static_cast<size_t>(width),
                                                     width, height, x, y, min_range);
                    ASSERT_EQ(textured[static_cast<size_t>(x)] != 0, expected)
                        << width << "x" << height << " at " << x << "," << y << ", range "
                        << min_range;
                    (expected ? textured_pixels : flat_pixels) += 1;
                }
            }
    }
    // Both answers were asked for, many times.
    EXPECT_GT(textured_pixels, 1000);
    EXPECT_GT(flat_pixels, 1000);
}

} // namespace
} // namespace stereod::sgm
