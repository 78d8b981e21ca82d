#include "ctl/output.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

namespace stereod {

namespace {

// The pipeline's order, which is also the order people read the table in.
constexpr std::array<const char*, 7> kStageOrder = {"rectify", "match", "depth",  "nearest",
                                                    "cloud",   "zones", "publish"};

} // namespace

nlohmann::ordered_json stageTimingsToJson(const StageTimings& timings)
{
    return {{"rectify", timings.rectify_ms},
            {"match", timings.match_ms},
            {"depth", timings.depth_ms},
            {"nearest", timings.nearest_ms},
            {"cloud", timings.cloud_ms}};
}

void printStageTable(std::FILE* out, const nlohmann::ordered_json& stage_ms)
{
    if (!stage_ms.is_object()) {
        return;
    }
    std::vector<std::pair<std::string, double>> rows;
    for (const char* stage : kStageOrder) {
        if (const auto it = stage_ms.find(stage); it != stage_ms.end() && it->is_number()) {
            rows.emplace_back(stage, it->get<double>());
        }
    }
    for (const auto& item : stage_ms.items()) {
        const std::string& stage = item.key();
        const bool known =
            std::find(kStageOrder.begin(), kStageOrder.end(), stage) != kStageOrder.end();
        if (!known && item.value().is_number()) {
            rows.emplace_back(stage, item.value().get<double>());
        }
    }
    double total_ms = 0.0;
    fmt::print(out, "  {:<10} {:>9}\n", "stage", "ms");
    for (const auto& [stage, ms] : rows) {
        fmt::print(out, "  {:<10} {:>9.2f}\n", stage, ms);
        total_ms += ms;
    }
    fmt::print(out, "  {:<10} {:>9.2f}\n", "total", total_ms);
}

std::pair<double, double> depthDisplayRange(const cv::Mat& depth_m)
{
    CV_Assert(depth_m.type() == CV_32FC1);
    std::vector<float> valid;
    valid.reserve(depth_m.total());
    for (int y = 0; y < depth_m.rows; ++y) {
        const float* row = depth_m.ptr<float>(y);
        for (int x = 0; x < depth_m.cols; ++x) {
            if (row[x] > 0.0f && std::isfinite(row[x])) {
                valid.push_back(row[x]);
            }
        }
    }
    if (valid.empty()) {
        return {1.0, 10.0};
    }
    const auto at = [&](double fraction) {
        const auto k =
            static_cast<std::ptrdiff_t>(fraction * static_cast<double>(valid.size() - 1));
        std::nth_element(valid.begin(), valid.begin() + k, valid.end());
        return static_cast<double>(valid[static_cast<std::size_t>(k)]);
    };
    const double low = at(0.01);
    const double high = at(0.99);
    // A flat scene still needs a range to map onto colours.
    return {low, std::max(high, low * 1.01 + 1e-3)};
}

void writeImagePng(const std::string& path, const cv::Mat& image)
{
    bool written = false;
    try {
        written = cv::imwrite(path, image);
    } catch (const cv::Exception& e) {
        throw std::runtime_error("cannot write " + path + ": " + e.what());
    }
    if (!written) {
        throw std::runtime_error("cannot write " + path +
                                 ": the image encoder refused it (check the directory and the "
                                 "extension)");
    }
}

} // namespace stereod
