#include "daemon/image_payload.hpp"

namespace stereod {

Payload imagePayload(std::string_view name, std::string_view format, const cv::Mat& mat)
{
    Payload payload;
    payload.name = name;
    payload.format = format;
    payload.width = mat.empty() ? 0 : mat.cols;
    payload.height = mat.empty() ? 0 : mat.rows;
    payload.bytes = matBytes(mat);
    return payload;
}

Payload colourPayload(std::string_view name, const cv::Mat& bgr)
{
    return imagePayload(name, kFormatRgb, bgr);
}

uint64_t matBytes(const cv::Mat& mat)
{
    return mat.empty() ? 0 : static_cast<uint64_t>(mat.total()) * mat.elemSize();
}

void appendMatBytes(std::string& out, const cv::Mat& mat)
{
    if (mat.empty())
        return;
    const std::size_t row_bytes = static_cast<std::size_t>(mat.cols) * mat.elemSize();
    if (mat.isContinuous()) {
        out.append(reinterpret_cast<const char*>(mat.data),
                   row_bytes * static_cast<std::size_t>(mat.rows));
        return;
    }
    for (int row = 0; row < mat.rows; ++row)
        out.append(reinterpret_cast<const char*>(mat.ptr(row)), row_bytes);
}

void appendBgrAsRgb(std::string& out, const cv::Mat& bgr)
{
    if (bgr.empty())
        return;
    const std::size_t row_bytes = static_cast<std::size_t>(bgr.cols) * 3;
    std::size_t at = out.size();
    out.resize(at + row_bytes * static_cast<std::size_t>(bgr.rows));
    for (int row = 0; row < bgr.rows; ++row) {
        const uint8_t* in = bgr.ptr<uint8_t>(row);
        char* dst = out.data() + at;
        for (std::size_t i = 0; i < row_bytes; i += 3) {
            dst[i] = static_cast<char>(in[i + 2]);
            dst[i + 1] = static_cast<char>(in[i + 1]);
            dst[i + 2] = static_cast<char>(in[i]);
        }
        at += row_bytes;
    }
}

} // namespace stereod
