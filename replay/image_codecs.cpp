#include "replay/image_codecs.hpp"

#include <csetjmp>
#include <cstdio>
#include <cstring>

// jpeglib.h needs size_t and FILE declared first.
#include <jerror.h>
#include <jpeglib.h>
#include <png.h>

namespace stereod {

namespace {

void appendMessage(std::string& printed, const char* prefix, const char* message)
{
    if (!printed.empty())
        printed += ';';
    printed += prefix;
    printed += message;
}

// ---- PNG ----

struct PngInput {
    const uint8_t* data;
    std::size_t size;
    std::size_t position;
    std::string* printed;
};

void pngRead(png_structp png, png_bytep to, png_size_t count)
{
    auto* input = static_cast<PngInput*>(png_get_io_ptr(png));
    if (count > input->size - input->position)
        png_error(png, "PNG input buffer is incomplete");
    std::memcpy(to, input->data + input->position, count);
    input->position += count;
}

// Must not return: libpng's default handler, which prints to stderr, runs if it does.
[[noreturn]] void pngError(png_structp png, png_const_charp message)
{
    auto* input = static_cast<PngInput*>(png_get_error_ptr(png));
    appendMessage(*input->printed, "libpng error: ", message);
    png_longjmp(png, 1);
}

void pngWarning(png_structp png, png_const_charp message)
{
    auto* input = static_cast<PngInput*>(png_get_error_ptr(png));
    appendMessage(*input->printed, "libpng warning: ", message);
}

struct PngRead {
    png_structp png = nullptr;
    png_infop info = nullptr;
    png_infop end = nullptr;
    std::vector<png_bytep> rows; // out here: not a local changed between setjmp and longjmp
    ~PngRead() { png_destroy_read_struct(&png, info ? &info : nullptr, end ? &end : nullptr); }
};

// No frame a longjmp crosses holds an object with a destructor, and no local of this one
// changes after the setjmp.
bool pngDecodeInto(PngRead& read, PngInput& input, bool colour, cv::Mat& out, bool& not_covered)
{
    if (setjmp(png_jmpbuf(read.png)) != 0)
        return false;
    png_set_read_fn(read.png, &input, pngRead);
    png_read_info(read.png, read.info);
    png_uint_32 width = 0, height = 0;
    int bit_depth = 0, colour_type = 0;
    png_get_IHDR(read.png, read.info, &width, &height, &bit_depth, &colour_type, nullptr, nullptr,
                 nullptr);
#ifdef PNG_eXIf_SUPPORTED
    // imdecode turns an image by its EXIF orientation: left to it.
    png_uint_32 exif_size = 0;
    png_bytep exif = nullptr;
    if (png_get_eXIf_1(read.png, read.info, &exif_size, &exif) != 0 && exif_size > 0) {
        not_covered = true;
        return false;
    }
#endif
    // The transforms of OpenCV's PNG decoder for an 8-bit, 1- or 3-channel result.
    if (bit_depth == 16)
        png_set_strip_16(read.png);
    png_set_strip_alpha(read.png);
    if (colour_type == PNG_COLOR_TYPE_PALETTE)
        png_set_palette_to_rgb(read.png);
    if ((colour_type & PNG_COLOR_MASK_COLOR) == 0 && bit_depth < 8)
        png_set_expand_gray_1_2_4_to_8(read.png);
    if ((colour_type & PNG_COLOR_MASK_COLOR) != 0 && colour)
        png_set_bgr(read.png);
    else if (colour)
        png_set_gray_to_rgb(read.png);
    else
        png_set_rgb_to_gray(read.png, 1, 0.299, 0.587);
    png_set_interlace_handling(read.png);
    png_read_update_info(read.png, read.info);
    // The caller checked the declared size against its limits before this call.
    out.create(static_cast<int>(height), static_cast<int>(width), colour ? CV_8UC3 : CV_8UC1);
    read.rows.resize(height);
    for (png_uint_32 y = 0; y < height; ++y)
        read.rows[y] = out.ptr<uint8_t>(static_cast<int>(y));
    png_read_image(read.png, read.rows.data());
    png_read_end(read.png, read.end);
#ifdef PNG_eXIf_SUPPORTED
    if (png_get_eXIf_1(read.png, read.end, &exif_size, &exif) != 0 && exif_size > 0) {
        not_covered = true;
        return false;
    }
#endif
    return true;
}

// ---- JPEG ----

struct JpegErrors {
    jpeg_error_mgr manager; // first: libjpeg hands back a pointer to it
    std::jmp_buf jump;
    std::string* printed;
};

void jpegOutput(j_common_ptr info)
{
    char message[JMSG_LENGTH_MAX];
    info->err->format_message(info, message);
    auto* errors = reinterpret_cast<JpegErrors*>(info->err);
    appendMessage(*errors->printed, "", message);
}

[[noreturn]] void jpegExit(j_common_ptr info)
{
    info->err->output_message(info);
    auto* errors = reinterpret_cast<JpegErrors*>(info->err);
    std::longjmp(errors->jump, 1);
}

struct JpegRead {
    jpeg_decompress_struct info{};
    bool created = false;
    bool all_rows = false; // out here: not a local changed between setjmp and longjmp
    ~JpegRead()
    {
        if (created)
            jpeg_destroy_decompress(&info);
    }
};

bool hasExif(const jpeg_decompress_struct& info)
{
    for (jpeg_saved_marker_ptr marker = info.marker_list; marker != nullptr; marker = marker->next)
        if (marker->marker == JPEG_APP0 + 1 && marker->data_length >= 6 &&
            std::memcmp(marker->data, "Exif\0\0", 6) == 0)
            return true;
    return false;
}

bool jpegDecodeInto(JpegRead& read, JpegErrors& errors, const std::vector<uint8_t>& bytes,
                    bool colour, cv::Mat& out, bool& not_covered)
{
    jpeg_decompress_struct& info = read.info;
    // An error after the last row (in the markers past it) leaves the image as imdecode
    // leaves it: decoded, with the error in what was printed.
    if (setjmp(errors.jump) != 0)
        return read.all_rows;
    jpeg_create_decompress(&info);
    read.created = true;
    jpeg_mem_src(&info, bytes.data(), static_cast<unsigned long>(bytes.size()));
    jpeg_save_markers(&info, JPEG_APP0 + 1, 0xffff);
    jpeg_read_header(&info, TRUE);
    // CMYK (OpenCV converts it itself) and an EXIF orientation: left to imdecode.
    if (info.num_components == 4 || hasExif(info)) {
        not_covered = true;
        return false;
    }
    info.out_color_space = colour ? JCS_EXT_BGR : JCS_GRAYSCALE;
    info.out_color_components = colour ? 3 : 1;
    jpeg_start_decompress(&info);
    // The caller checked the declared size against its limits before this call.
    out.create(static_cast<int>(info.output_height), static_cast<int>(info.output_width),
               colour ? CV_8UC3 : CV_8UC1);
    while (info.output_scanline < info.output_height) {
        JSAMPROW row = out.ptr<uint8_t>(static_cast<int>(info.output_scanline));
        jpeg_read_scanlines(&info, &row, 1);
    }
    read.all_rows = true;
    jpeg_finish_decompress(&info);
    return true;
}

} // namespace

CodecResult decodePng(const std::vector<uint8_t>& bytes, bool colour, cv::Mat& out,
                      std::string& printed)
{
    printed.clear();
    PngInput input{bytes.data(), bytes.size(), 0, &printed};
    PngRead read;
    read.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &input, pngError, pngWarning);
    if (read.png == nullptr) {
        printed = "libpng error: cannot create a read struct";
        return CodecResult::Failed;
    }
    read.info = png_create_info_struct(read.png);
    read.end = png_create_info_struct(read.png);
    if (read.info == nullptr || read.end == nullptr) {
        printed = "libpng error: cannot create an info struct";
        return CodecResult::Failed;
    }
    bool not_covered = false;
    if (pngDecodeInto(read, input, colour, out, not_covered))
        return CodecResult::Decoded;
    out.release();
    return not_covered ? CodecResult::NotCovered : CodecResult::Failed;
}

CodecResult decodeJpeg(const std::vector<uint8_t>& bytes, bool colour, cv::Mat& out,
                       std::string& printed)
{
    printed.clear();
    JpegErrors errors{};
    errors.printed = &printed;
    JpegRead read;
    read.info.err = jpeg_std_error(&errors.manager);
    errors.manager.output_message = jpegOutput;
    errors.manager.error_exit = jpegExit;
    bool not_covered = false;
    if (jpegDecodeInto(read, errors, bytes, colour, out, not_covered))
        return CodecResult::Decoded;
    out.release();
    return not_covered ? CodecResult::NotCovered : CodecResult::Failed;
}

} // namespace stereod
