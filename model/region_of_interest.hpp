#pragma once
// Where in the image the nearest object is looked for (nearest.roi), as the configuration
// sets it and `status` reports it.
//
// Plain values. Units: fractions of the rectified left image (0..1).

namespace stereod {

// A rectangle in fractions of the rectified left image (0..1), so that it survives a
// change of resolution. x/y are the top-left corner.
struct RegionOfInterest {
    double x = 0.25;
    double y = 0.25;
    double width = 0.5;
    double height = 0.5;
};

} // namespace stereod
