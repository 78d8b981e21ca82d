#pragma once
// Files the pipeline's results are written to and read from (formats in DESIGN.md):
//  - disparity: .pfm float32, Middlebury convention (invalid = +inf), or .png uint16 with
//    disparity * 256, KITTI convention (0 = invalid);
//  - depth: .png uint16 in millimetres, 0 = invalid;
//  - point cloud: .ply with x y z in metres (rectified left camera), intensity, and the
//    colour when the left camera gives one;
//  - a colourised depth picture for people.
// Every writer throws std::runtime_error naming the file and what failed.

#include <string>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "pipeline/stereo_processor.hpp"

namespace stereod {

// Disparity (CV_32FC1, pixels, invalid = +inf or NaN) to .pfm or .png by the extension.
void writeDisparity(const std::string& path, const cv::Mat& disparity);
// Reads .pfm (returned as is) or KITTI .png (0 becomes +inf); CV_32FC1.
cv::Mat readDisparity(const std::string& path);

// Depth (CV_32FC1, metres, invalid = 0) as .png uint16 millimetres; depths beyond
// 65.535 m are written as 0 (invalid), never clipped to a wrong value.
void writeDepthPng(const std::string& path, const cv::Mat& depth_m);
// Converts into a preallocated CV_16UC1 buffer (the service's snapshot path).
void depthToMillimetres(const cv::Mat& depth_m, cv::Mat& depth_mm);
// Reads a depth .png (uint16 millimetres) back to CV_32FC1 metres, 0 = invalid.
cv::Mat readDepthPng(const std::string& path);

// Per-pixel match confidence (CV_8UC1: 0 = no disparity, 1..255) as an 8-bit .png.
void writeConfidencePng(const std::string& path, const cv::Mat& confidence);

// Binary little-endian .ply, float x y z intensity, and with `colours` (one per point,
// same order; empty for a grey cloud) uchar red green blue after them, the properties
// viewers such as MeshLab and CloudCompare show as the points' colour. Throws
// std::invalid_argument when colours are given for a different number of points.
void writePly(const std::string& path, const std::vector<CloudPoint>& cloud,
              const std::vector<CloudColour>& colours = {});

// A BGR picture of the depth: near is warm, far is cool, invalid is black. The scale
// runs from min_depth_m to max_depth_m.
cv::Mat colorizeDepth(const cv::Mat& depth_m, double min_depth_m, double max_depth_m);
void writeColorizedDepth(const std::string& path, const cv::Mat& depth_m, double min_depth_m,
                         double max_depth_m);

} // namespace stereod
