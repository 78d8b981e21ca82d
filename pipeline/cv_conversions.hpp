#pragma once
// The model's plain types (model/) to and from OpenCV's, in one place: the model stays
// free of OpenCV, and the pipeline, which computes with OpenCV, converts here and nowhere
// else by hand.
//
// Pure functions; any thread. Units unchanged by every conversion.

#include <opencv2/core/matx.hpp>
#include <opencv2/core/types.hpp>

#include "model/image_size.hpp"
#include "model/vec3.hpp"

namespace stereod {

inline cv::Size toCv(ImageSize size)
{
    return {size.width, size.height};
}

inline ImageSize toImageSize(cv::Size size)
{
    return {size.width, size.height};
}

inline cv::Vec3d toCv(const Vec3& v)
{
    return {v[0], v[1], v[2]};
}

inline Vec3 toVec3(const cv::Vec3d& v)
{
    return {v[0], v[1], v[2]};
}

} // namespace stereod
