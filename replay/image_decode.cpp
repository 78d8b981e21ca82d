#include "replay/image_decode.hpp"

#include <cerrno>

#include <opencv2/imgcodecs.hpp>

#include "replay/image_codecs.hpp"
#include "replay/image_file.hpp"
#include "replay/image_message.hpp"

namespace stereod {

namespace {

std::string sizeText(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

// Decodes `bytes` as 8-bit grey (or BGR with IMREAD_COLOR) into `out`, with what the image
// libraries have to say (libpng's "libpng error: ...", libjpeg's "Corrupt JPEG data: ...")
// in `printed`: PNG and JPEG by libpng and libjpeg with handlers that collect it
// (replay/image_codecs.hpp), other formats, and the few files those leave (CMYK, EXIF
// orientation), by imdecode. Throws what imdecode throws.
void decodeQuietly(const std::vector<uint8_t>& bytes, ImageFormat format, cv::Mat& out,
                   std::string& printed, int flags = cv::IMREAD_GRAYSCALE)
{
    printed.clear();
    const bool colour = flags == cv::IMREAD_COLOR;
    CodecResult result = CodecResult::NotCovered;
    if (format == ImageFormat::Png)
        result = decodePng(bytes, colour, out, printed);
    else if (format == ImageFormat::Jpeg)
        result = decodeJpeg(bytes, colour, out, printed);
    if (result != CodecResult::NotCovered)
        return;
    printed.clear();
    const cv::Mat encoded(1, static_cast<int>(bytes.size()), CV_8UC1,
                          const_cast<uint8_t*>(bytes.data()));
    out = cv::imdecode(encoded, flags);
}

} // namespace

void pngGreyFromBgr(const cv::Mat& bgr, cv::Mat& grey)
{
    // png_set_rgb_to_gray(png, 1, 0.299, 0.587), as OpenCV calls it: libpng keeps the
    // weights as 15-bit integers, each truncated (0.299 * 32768 = 9797.6 -> 9797, 0.587 *
    // 32768 = 19234.8 -> 19234, blue the rest of 32768: 13737), and truncates the sum
    // (png_do_rgb_to_gray, 8-bit without gamma).
    constexpr uint32_t kRed = 9797, kGreen = 19234, kBlue = 32768 - kRed - kGreen;
    grey.create(bgr.size(), CV_8UC1);
    for (int row = 0; row < bgr.rows; ++row) {
        const uint8_t* in = bgr.ptr<uint8_t>(row);
        uint8_t* to = grey.ptr<uint8_t>(row);
        for (int col = 0; col < bgr.cols; ++col, in += 3)
            to[col] = static_cast<uint8_t>((kBlue * in[0] + kGreen * in[1] + kRed * in[2]) >> 15);
    }
}

bool decodeImageFile(const std::string& path, cv::Size expected, const std::string& expected_what,
                     std::vector<uint8_t>& bytes, cv::Mat& out, std::string& reason, int& code,
                     cv::Mat* colour)
{
    // `out` and `colour` keep their buffers from one call to the next (the decoders write
    // into them when the size and type match): a replay decodes into the same images every
    // frame. Every failure empties both.
    const auto fail = [&](std::string why) {
        reason = std::move(why);
        out.release();
        if (colour != nullptr)
            colour->release();
        return false;
    };
    std::string why;
    code = readImageFile(path, kMaxImageFileBytes, bytes, why);
    if (code != 0)
        return fail(std::move(why));
    code = EINVAL;
    const ImageHeader header = parseImageHeader(bytes);
    if (!header.problem.empty())
        return fail("not a readable image: " + header.problem);
    if (!header.complete) {
        return fail(header.format == ImageFormat::Png
                        ? "is cut short: a truncated PNG (no IEND chunk at its end)"
                        : "is cut short: a truncated JPEG (no end-of-image marker)");
    }
    if (!header.size.empty()) {
        if (!expected.empty() && header.size != expected)
            return fail("is " + sizeText(header.size) + ", " + expected_what + " (not decoded)");
        if (expected.empty() &&
            int64_t{header.size.width} * header.size.height > kMaxReplayPixels) {
            return fail("declares " + sizeText(header.size) +
                        " pixels, more than a frame may have (not decoded)");
        }
    }
    // A colour PNG whose grey is a weighting of its RGB is decoded once, in colour, and its
    // grey made from that exactly as libpng makes it: half the work of two decodes, the
    // same grey (the tests compare every 8-bit colour).
    const bool once = colour != nullptr && header.grey_from_rgb;
    std::string printed;
    try {
        if (once) {
            decodeQuietly(bytes, header.format, *colour, printed, cv::IMREAD_COLOR);
            if (!colour->empty() && colour->type() == CV_8UC3)
                pngGreyFromBgr(*colour, out);
            else
                out.release();
        } else {
            decodeQuietly(bytes, header.format, out, printed);
        }
    } catch (const std::exception& e) { // cv::Exception, or memory that ran out
        return fail(std::string("cannot decode: ") + e.what());
    }
    if (out.empty()) {
        return fail("not a readable image (corrupt, truncated or of an unknown format)" +
                    (printed.empty() ? std::string() : ": " + printed));
    }
    // libjpeg says so when it met corrupt data it filled in (grey, or the last row):
    // such a frame is not the picture the camera took. (libpng's warnings, e.g. about a
    // colour profile, leave the pixels alone.)
    if (header.format == ImageFormat::Jpeg && !printed.empty())
        return fail("corrupt: " + printed);
    if (!expected.empty() && out.size() != expected)
        return fail("is " + sizeText(out.size()) + ", " + expected_what);
    // Other colour files: the colour beside the grey, decoded once more, so that the grey
    // stays exactly the decoder's own (a JPEG's luma, which its colour cannot give back;
    // libpng's grey with the file's gamma), as for a grey replay.
    if (colour != nullptr && header.colour && !once) {
        try {
            decodeQuietly(bytes, header.format, *colour, printed, cv::IMREAD_COLOR);
        } catch (const std::exception&) {
            colour->release();
        }
        if (colour->size() != out.size() || colour->type() != CV_8UC3)
            colour->release();
    } else if (colour != nullptr && !once) {
        colour->release(); // a grey file: no colour beside its grey
    }
    code = 0;
    return true;
}

} // namespace stereod
