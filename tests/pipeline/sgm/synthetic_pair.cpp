#include "tests/pipeline/sgm/synthetic_pair.hpp"

namespace stereod::sgm::test {
namespace {

uint32_t hash(uint32_t a, uint32_t b, uint32_t c, uint32_t seed)
{
    uint32_t h = seed ^ 0x9E3779B9u;
    for (uint32_t v : {a, b, c}) {
        h ^= v + 0x7F4A7C15u + (h << 6) + (h >> 2);
        h *= 0x85EBCA6Bu;
        h ^= h >> 13;
    }
    return h;
}

uint8_t texture(int layer, int u, int y, uint32_t seed)
{
    const auto l = static_cast<uint32_t>(layer);
    const auto fine = hash(l, static_cast<uint32_t>(u), static_cast<uint32_t>(y), seed) & 0xFFu;
    const auto coarse =
        hash(l + 1000u, static_cast<uint32_t>(u >> 3), static_cast<uint32_t>(y >> 3), seed) & 0xFFu;
    return static_cast<uint8_t>((fine + coarse) / 2);
}

// The front layer covering left-view column u of row y, or -1.
int frontLayer(const std::vector<Layer>& layers, int u, int y)
{
    for (int i = static_cast<int>(layers.size()) - 1; i >= 0; --i) {
        const Layer& l = layers[static_cast<size_t>(i)];
        if (u >= l.x0 && u < l.x1 && y >= l.y0 && y < l.y1)
            return i;
    }
    return -1;
}

// The front layer seen at right-view column xr of row y, or -1.
int frontLayerRight(const std::vector<Layer>& layers, int xr, int y)
{
    for (int i = static_cast<int>(layers.size()) - 1; i >= 0; --i) {
        const Layer& l = layers[static_cast<size_t>(i)];
        const int u = xr + l.disparity_px;
        if (u >= l.x0 && u < l.x1 && y >= l.y0 && y < l.y1)
            return i;
    }
    return -1;
}

} // namespace

uint64_t Random::next()
{
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

int Random::uniform(int lo, int hi)
{
    const auto span = static_cast<uint64_t>(static_cast<int64_t>(hi) - lo + 1);
    return lo + static_cast<int>(next() % span);
}

SyntheticPair makeSyntheticPair(int width, int height, const std::vector<Layer>& layers,
                                uint32_t seed)
{
    SyntheticPair pair;
    pair.width = width;
    pair.height = height;
    const size_t area = static_cast<size_t>(width) * static_cast<size_t>(height);
    pair.left.assign(area, 0);
    pair.right.assign(area, 0);
    pair.truth_px.assign(area, 0);
    pair.occluded.assign(area, 1);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const size_t i = pair.at(x, y);
            const int front = frontLayer(layers, x, y);
            if (front >= 0) {
                const int d = layers[static_cast<size_t>(front)].disparity_px;
                pair.left[i] = texture(front, x, y, seed);
                pair.truth_px[i] = d;
                pair.occluded[i] =
                    (x - d < 0 || frontLayerRight(layers, x - d, y) != front) ? 1 : 0;
            }
            const int front_right = frontLayerRight(layers, x, y);
            if (front_right >= 0)
                pair.right[i] =
                    texture(front_right, x + layers[static_cast<size_t>(front_right)].disparity_px,
                            y, seed);
        }
    return pair;
}

} // namespace stereod::sgm::test
