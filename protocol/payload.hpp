#pragma once
// The binary payloads that follow some replies and events (docs/protocol.md, "Binary
// payloads"): their formats, their descriptors (the entries of `payloads` and the depth
// event's header), and how a client checks what it is told before reading. One definition
// for the service and its clients, without OpenCV: the service's images as payloads are
// daemon/image_payload.hpp.
//
// Payload bytes are in host order, which the protocol fixes as little-endian; both sides
// send and read them in place.
//
// Reentrant: every function here is pure or writes only into the caller's buffer.

#include <bit>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>

#include "model/cloud_point.hpp"
#include "protocol/reply.hpp"

namespace stereod {

static_assert(std::endian::native == std::endian::little,
              "payloads are sent and read in place: add byte swapping for big-endian hosts");
static_assert(sizeof(CloudPoint) == 16 && std::is_trivially_copyable_v<CloudPoint>,
              "an f32_xyzi point travels as four float32");

// The payload formats.
inline constexpr std::string_view kFormatDepthMm = "u16_mm";           // uint16 mm, 0 = none
inline constexpr std::string_view kFormatDepthM = "f32_m";             // float32 m, 0 = none
inline constexpr std::string_view kFormatDisparityPx = "f32_px";       // float32 px, inf = none
inline constexpr std::string_view kFormatGray = "u8_gray";             // uint8 intensity
inline constexpr std::string_view kFormatConfidence = "u8_confidence"; // 0 = no disparity
inline constexpr std::string_view kFormatCloud = "f32_xyzi";           // CloudPoint, 16 bytes
// Colour, 3 bytes a pixel or a point in the order red, green, blue.
inline constexpr std::string_view kFormatRgb = "u8_rgb";
static_assert(sizeof(CloudColour) == 3, "a cloud colour travels as three bytes r, g, b");

// One payload's descriptor. Images have a width and a height; the cloud and its colours
// have points.
struct Payload {
    std::string name; // a snapshot item's name (protocol/request.hpp), raw_left, ...
    std::string format;
    int width = 0;
    int height = 0;
    bool per_point = false; // a cloud or its colours: `points`, no width and height
    std::size_t points = 0;
    std::size_t bytes = 0;
    std::optional<int64_t> stamp_ns; // capture time of a raw frame
};

// The descriptor of `points` cloud points.
Payload cloudPayload(std::size_t points);

// The descriptor of the colours of `points` cloud points (cloud_colour, u8_rgb).
Payload cloudColourPayload(std::size_t points);

// Appends the descriptor as a JSON object: name, format, then points and bytes (the
// cloud) or width, height and bytes (an image), then stamp_ns when there is one.
// Allocates nothing once `out` has the capacity.
void appendPayloadJson(std::string& out, const Payload& payload);

// The same object, for composing replies.
Json payloadToJson(const Payload& payload);

// The `bytes` of a header or descriptor: 0 when absent, nullopt when it is not a count.
std::optional<std::size_t> payloadBytesFromJson(const Json& header);

// Reads a descriptor; missing fields stay at their defaults. nullopt when `bytes` is not a
// count (the client cannot know how much to read past).
std::optional<Payload> payloadFromJson(const Json& header);

// Whether an image payload has width x height x `pixel_bytes` bytes (and a size).
bool imagePayloadAddsUp(const Payload& payload, std::size_t pixel_bytes);
// An OpenCV type (CV_16UC1 is 2) is not a pixel's bytes: say sizeof(uint16_t), or
// CV_ELEM_SIZE(type).
bool imagePayloadAddsUp(const Payload& payload, int) = delete;

// Whether a cloud payload has 16 bytes per point.
bool cloudPayloadAddsUp(const Payload& payload);

// Whether a u8_rgb payload has 3 bytes per pixel (an image) or per point (cloud colours);
// an empty image (0 x 0, 0 bytes: a grey source) adds up.
bool colourPayloadAddsUp(const Payload& payload);

} // namespace stereod
