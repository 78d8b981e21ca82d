#include "replay/image_message.hpp"

#include <new>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "ros2/messages.hpp"

namespace stereod {

namespace {

struct EncodingSpec {
    const char* name;
    int channels;
    int conversion; // to grey: cv::COLOR_*, kCopy (as it is) or kLuma (YUV 4:2:2's luma)
    int colour;     // to BGR: cv::COLOR_*, kCopy (already BGR) or kNone (no colour)
    int luma;       // YUV 4:2:2: the channel holding the luma
};

constexpr int kCopy = -1;
constexpr int kNone = -2;
constexpr int kLuma = -3;

constexpr EncodingSpec kEncodings[] = {
    {"mono8", 1, kCopy, kNone, 0},
    {"8UC1", 1, kCopy, kNone, 0},
    {"rgb8", 3, cv::COLOR_RGB2GRAY, cv::COLOR_RGB2BGR, 0},
    {"bgr8", 3, cv::COLOR_BGR2GRAY, kCopy, 0},
    {"rgba8", 4, cv::COLOR_RGBA2GRAY, cv::COLOR_RGBA2BGR, 0},
    {"bgra8", 4, cv::COLOR_BGRA2GRAY, cv::COLOR_BGRA2BGR, 0},
    // ROS's yuv422 is UYVY (luma second), yuv422_yuy2 YUYV (luma first).
    {"yuv422", 2, kLuma, cv::COLOR_YUV2BGR_UYVY, 1},
    {"yuv422_yuy2", 2, kLuma, cv::COLOR_YUV2BGR_YUYV, 0},
};

std::string sizeText(uint64_t width, uint64_t height)
{
    return std::to_string(width) + "x" + std::to_string(height);
}

// Both public forms: `colour` null when the caller wants none.
bool decode(std::string_view message, cv::Size expected, cv::Mat& out, cv::Mat* colour,
            std::string& reason) noexcept
{
    try {
        ros2::ImageView image;
        try {
            image = ros2::parseImage(message);
        } catch (const ros2::CdrError& e) {
            reason = e.what();
            return false;
        }
        const EncodingSpec* spec = nullptr;
        for (const EncodingSpec& candidate : kEncodings)
            if (image.encoding == candidate.name)
                spec = &candidate;
        if (spec == nullptr) {
            reason = "image encoding '" + image.encoding +
                     "' is not replayed (mono8, rgb8, bgr8, rgba8, bgra8, yuv422 and "
                     "yuv422_yuy2 are)";
            return false;
        }
        // Every product in 64 bits: width and height are the file's word, up to 2^32 each.
        const uint64_t width = image.width;
        const uint64_t height = image.height;
        const uint64_t row_bytes = width * static_cast<uint64_t>(spec->channels);
        if (width == 0 || height == 0) {
            reason = "image of " + sizeText(width, height) + " has no pixels";
            return false;
        }
        if (width * height > static_cast<uint64_t>(kMaxReplayPixels)) {
            reason = "image declares " + sizeText(width, height) +
                     " pixels, more than a frame may have (8192x8192; not decoded)";
            return false;
        }
        if (spec->conversion == kLuma && width % 2 != 0) {
            reason = "image of " + sizeText(width, height) + " " + image.encoding +
                     " has an odd width: 4:2:2 pixels come in pairs";
            return false;
        }
        if (image.step < row_bytes) {
            reason = "image of " + sizeText(width, height) + " " + image.encoding + " has step " +
                     std::to_string(image.step) + ", less than its row of " +
                     std::to_string(row_bytes) + " bytes";
            return false;
        }
        // parseImage() checked step x height against the data; the pixels fit in int now.
        const cv::Size size(static_cast<int>(width), static_cast<int>(height));
        if (!expected.empty() && size != expected) {
            reason = "image is " + sizeText(width, height) + ", " +
                     sizeText(static_cast<uint64_t>(expected.width),
                              static_cast<uint64_t>(expected.height)) +
                     " expected (not decoded)";
            return false;
        }
        auto* data = const_cast<char*>(image.data.data()); // wrapped read-only, then copied
        const cv::Mat view(size, CV_MAKETYPE(CV_8U, spec->channels), data, image.step);
        if (spec->conversion == kCopy)
            view.copyTo(out);
        else if (spec->conversion == kLuma)
            cv::extractChannel(view, out, spec->luma);
        else
            cv::cvtColor(view, out, spec->conversion);
        if (colour != nullptr) {
            if (spec->colour == kNone)
                colour->release();
            else if (spec->colour == kCopy)
                view.copyTo(*colour);
            else
                cv::cvtColor(view, *colour, spec->colour);
        }
        return true;
    } catch (const cv::Exception& e) {
        reason = std::string("image not decoded: ") + e.what();
    } catch (const std::bad_alloc&) {
        reason = "image not decoded: out of memory";
    } catch (const std::exception& e) {
        reason = std::string("image not decoded: ") + e.what();
    }
    out.release();
    if (colour != nullptr)
        colour->release();
    return false;
}

} // namespace

bool decodeImageMessage(std::string_view message, cv::Size expected, cv::Mat& out,
                        std::string& reason) noexcept
{
    return decode(message, expected, out, nullptr, reason);
}

bool decodeImageMessage(std::string_view message, cv::Size expected, cv::Mat& out, cv::Mat& colour,
                        std::string& reason) noexcept
{
    return decode(message, expected, out, &colour, reason);
}

} // namespace stereod
