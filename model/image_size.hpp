#pragma once
// The size of an image in pixels, without OpenCV (pipeline/cv_conversions.hpp converts it to and
// from cv::Size where OpenCV needs one).
//
// Plain values. Units: pixels.

namespace stereod {

struct ImageSize {
    int width = 0;
    int height = 0;

    int area() const { return width * height; }
    friend bool operator==(const ImageSize&, const ImageSize&) = default;
};

} // namespace stereod
