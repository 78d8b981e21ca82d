#pragma once
// A bag's camera image as the pipeline takes it: one serialized sensor_msgs/msg/Image
// (CDR, ros2/messages.hpp) decoded into 8-bit grayscale (and, on request, its colour as
// BGR beside it), after every size the
// message declares has been checked against the bytes it carries and against the largest
// frame a replay may have, in 64-bit arithmetic, before anything is allocated or handed
// to OpenCV. A pure function of its input, so that it is unit-tested and fuzzed on its own
// (tests/replay/fuzz_image_message.cpp).
//
// Units: sizes in pixels, steps in bytes per row.
// Reentrant: no state outside the arguments.

#include <cstdint>
#include <string>
#include <string_view>

#include <opencv2/core/mat.hpp>

namespace stereod {

// The most pixels a replayed frame may have, whatever its source (a recording's image
// files or a bag's messages): 8192x8192, beyond any stereo camera's frame. Larger images
// are refused before they are decoded.
inline constexpr int64_t kMaxReplayPixels = int64_t{8192} * 8192;

// Decodes `message` into `out` as CV_8UC1: mono8 (and 8UC1) as is, rgb8, bgr8, rgba8 and
// bgra8 converted. `expected`: the size the image must have (the replay's frame size, or
// the pair's left image for its right one); empty: any size up to kMaxReplayPixels. Never
// throws: false, with `reason` saying what is wrong (the field and its value), for a
// message that does not parse, an encoding not replayed, sizes that do not fit the data
// or overflow, an image larger than allowed or not of `expected` size (none of these is
// decoded), and for what OpenCV refuses or cannot allocate.
bool decodeImageMessage(std::string_view message, cv::Size expected, cv::Mat& out,
                        std::string& reason) noexcept;

// The same, and the image's colour into `colour` (CV_8UC3, BGR) when its encoding has
// colour: rgb8, bgr8, rgba8, bgra8, and YUV 4:2:2 (yuv422: UYVY, yuv422_yuy2: YUYV; BT.601
// limited range, their grey the luma plane; the width must be even); `colour` is released
// for mono8. The grey is exactly what the call above gives.
bool decodeImageMessage(std::string_view message, cv::Size expected, cv::Mat& out, cv::Mat& colour,
                        std::string& reason) noexcept;

} // namespace stereod
