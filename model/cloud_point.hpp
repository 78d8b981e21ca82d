#pragma once
// The point cloud's elements as the pipeline makes them and the protocol sends them
// (f32_xyzi, u8_rgb: docs/protocol.md): laid out as they travel, so that a cloud is sent
// and read in place.
//
// Plain values. Units: metres for positions; 0..255 for intensity and colour.

#include <cstdint>

namespace stereod {

// One point of the cloud: camera frame of the rectified left camera (x right, y down,
// z forward), metres; intensity from the rectified left image.
struct CloudPoint {
    float x, y, z;
    float intensity;
};

// The colour of a cloud point, from the rectified colour left image, 0..255 per channel.
struct CloudColour {
    uint8_t r, g, b;
};

} // namespace stereod
