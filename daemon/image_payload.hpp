#pragma once
// The service's images as binary payloads (docs/protocol.md, "Binary payloads"): the
// descriptor of an OpenCV image and its bytes as they are sent. The formats and the
// descriptors themselves are the protocol's (protocol/payload.hpp), which knows no OpenCV;
// this is the side that writes images.
//
// Reentrant: every function here is pure or writes only into the caller's buffer.

#include <cstdint>
#include <string>
#include <string_view>

#include <opencv2/core/mat.hpp>

#include "protocol/payload.hpp"

namespace stereod {

// The descriptor of `mat`'s pixels as the service sends them (an empty image: 0 bytes).
Payload imagePayload(std::string_view name, std::string_view format, const cv::Mat& mat);

// The descriptor of a BGR colour image sent as u8_rgb (an empty image: 0 bytes).
Payload colourPayload(std::string_view name, const cv::Mat& bgr);

// Bytes of `mat`'s pixels; 0 for an empty image.
uint64_t matBytes(const cv::Mat& mat);

// Appends `mat`'s pixels row by row, without padding.
void appendMatBytes(std::string& out, const cv::Mat& mat);

// Appends a CV_8UC3 BGR image's pixels as u8_rgb (red first), row by row; nothing for an
// empty image. Allocates nothing once `out` has the capacity.
void appendBgrAsRgb(std::string& out, const cv::Mat& bgr);

} // namespace stereod
