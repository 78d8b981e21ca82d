#include "tests/pipeline/scene_truth.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include <opencv2/imgcodecs.hpp>

#include "pipeline/depth_io.hpp"
#include "tests/support/data_paths.hpp"

namespace stereod::test {

std::vector<SceneTruth> scenesWithTruth()
{
    namespace fs = std::filesystem;
    const std::string data = sharedDataDir() + "/";
    const auto scene = [&](std::string name, const std::string& left, const std::string& right,
                           const std::string& truth, double divisor) {
        return SceneTruth{std::move(name), data + left, data + right, data + truth, divisor};
    };
    std::vector<SceneTruth> list = {
        scene("tsukuba", "middlebury/tsukuba/im3.png", "middlebury/tsukuba/im4.png",
              "middlebury/tsukuba/disp3.pgm", 16),
        scene("venus", "middlebury/venus/im2.png", "middlebury/venus/im6.png",
              "middlebury/venus/disp2.pgm", 8),
    };
    for (const char* n : {"Art", "Books", "Dolls", "Laundry", "Moebius", "Reindeer"}) {
        const std::string d = std::string("middlebury2005/") + n + "/";
        list.push_back(scene(n, d + "view1.png", d + "view5.png", d + "disp1.png", 3));
    }
    for (const char* n :
         {"Adirondack", "ArtL", "Jadeplant", "Motorcycle", "Piano", "Pipes", "Playroom"}) {
        const std::string d = std::string("middlebury2014/") + n + "/";
        list.push_back(scene(n, d + "im0.png", d + "im1.png", d + "disp0GT.pfm", 1));
    }
    list.push_back(scene("eth3d", "eth3d/playground_1l/im0.png", "eth3d/playground_1l/im1.png",
                         "eth3d/playground_1l/disp0.pfm", 1));
    const std::string kitti = "kitti2012/000070/";
    if (fs::is_directory(data + kitti + "disp_noc"))
        for (const auto& entry : fs::directory_iterator(data + kitti + "disp_noc")) {
            const std::string file = entry.path().filename().string();
            list.push_back(scene("kitti", kitti + "image_0/" + file, kitti + "image_1/" + file,
                                 kitti + "disp_noc/" + file, 256));
        }
    return list;
}

cv::Mat loadTruthPx(const SceneTruth& scene)
{
    cv::Mat truth;
    if (scene.truth_path.ends_with(".pfm")) {
        truth = readDisparity(scene.truth_path);
    } else {
        const cv::Mat raw = cv::imread(scene.truth_path, cv::IMREAD_UNCHANGED);
        raw.convertTo(truth, CV_32FC1, 1.0 / scene.divisor);
    }
    const cv::Mat known = (truth > 0) & (truth < 1e6);
    truth.setTo(0, ~known);
    return truth;
}

int referenceRange(const cv::Mat& truth_px)
{
    double largest = 0;
    cv::minMaxLoc(truth_px, nullptr, &largest);
    return std::max(16, static_cast<int>(std::ceil(largest * 1.05 / 16.0)) * 16);
}

} // namespace stereod::test
