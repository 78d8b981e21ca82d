#pragma once
// The model's plain types (model/) to and from OpenCV's, in one place: the model stays
// free of OpenCV, and the pipeline, which computes with OpenCV, converts here and nowhere
// else by hand.
//
// Pure functions; any thread. Units unchanged by every conversion.

#include <opencv2/core/types.hpp>

#include "model/image_size.hpp"

namespace stereod {

inline cv::Size toCv(ImageSize size)
{
    return {size.width, size.height};
}

inline ImageSize toImageSize(cv::Size size)
{
    return {size.width, size.height};
}

} // namespace stereod
