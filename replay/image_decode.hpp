#pragma once
// Decoding one image file of a recording for the replay (replay/replay_source.hpp): read
// without trusting it (replay/image_file.hpp: a bounded read, the header's size checked
// before any pixel is decoded), decoded to 8-bit grey as the matcher sees it, and on
// request its colour beside it.
//
// Reentrant: PNG and JPEG are decoded by libpng and libjpeg with handlers that collect
// what they have to say (libpng's "libpng error: ...", libjpeg's "Corrupt JPEG data: ...")
// into the reason (replay/image_codecs.hpp); nothing goes to stderr and no process-wide
// state (fd 2, a lock) is touched, so calls from several threads run side by side.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

namespace stereod {

// An image file larger than this is refused unread (a 1920x1080 PNG is a few MB).
inline constexpr std::size_t kMaxImageFileBytes = 64u << 20;

// Decodes the image file at `path` as 8-bit grayscale into `out` (its buffer reused when
// it has the image's size and type; PNG and JPEG decode into it), reading it into `bytes` first (a
// bounded read of a regular file, capacity kept) and refusing it before decoding when its header
// says it is not `expected`
// (`expected_what` says what that is), or, with no size expected yet, larger than
// kMaxReplayPixels; or cut short. With `colour`, a colour file's colour goes there too
// (CV_8UC3 BGR; released for a grey file), and `out` is still exactly the grey decode of
// the file: a colour PNG whose header allows it (ImageHeader::grey_from_rgb, as
// `stereoctl record` writes them) is decoded once, in colour, its grey pngGreyFromBgr();
// other colour files (JPEG, PNG with a gamma or 16-bit samples) are decoded twice. On
// failure says why, with the errno: ENOENT when missing, EINVAL for a file that is no
// usable image.
bool decodeImageFile(const std::string& path, cv::Size expected, const std::string& expected_what,
                     std::vector<uint8_t>& bytes, cv::Mat& out, std::string& reason, int& code,
                     cv::Mat* colour = nullptr);

// The grey libpng gives for an 8-bit colour PNG without gamma (ImageHeader::grey_from_rgb)
// when OpenCV decodes it as grey, made from its colour decode `bgr` (CV_8UC3) into `grey`
// (CV_8UC1, reallocated only when its size differs): bit for bit the same.
void pngGreyFromBgr(const cv::Mat& bgr, cv::Mat& grey);

} // namespace stereod
