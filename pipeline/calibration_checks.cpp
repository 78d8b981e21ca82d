#include "pipeline/calibration_checks.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <initializer_list>

#include "pipeline/cv_conversions.hpp"

namespace stereod::calibration_detail {

namespace {

// editing one by hand may round to 6.
constexpr double kRotationTolerance = 1e-5;
// Relative tolerance for quantities that appear twice in a full calibration (P2 vs |T|,
// Q vs P1/P2): they must agree, but need not be bit-identical.
constexpr double kConsistencyTolerance = 1e-2;

} // namespace

std::string describeSize(cv::Size size)
{
    return std::to_string(size.width) + "x" + std::to_string(size.height);
}

std::string formatNumber(double value)
{
    // Shortest text that reads back to the same double: exact round trips, and files a
    // person can read (0.16, not 0.16000000000000000333).
    // Plain decimals (0.0008, not 8e-04) unless they get long (1e+20, 1e-12).
    constexpr size_t kLongestPlain = 20;
    std::array<char, 400> text{};
    const auto fixed =
        std::to_chars(text.data(), text.data() + text.size(), value, std::chars_format::fixed);
    if (fixed.ec == std::errc() && static_cast<size_t>(fixed.ptr - text.data()) <= kLongestPlain)
        return std::string(text.data(), fixed.ptr);
    const auto shortest = std::to_chars(text.data(), text.data() + text.size(), value);
    return std::string(text.data(), shortest.ptr);
}

[[noreturn]] void fail(const std::string& origin, int line, const std::string& key,
                       const std::string& problem)
{
    throwCalibrationError(origin, line, key, problem);
}
namespace {

// ---------------------------------------------------------------------------------------
// Validation, shared by the loader and by calibrations assembled in code.

class Validator {
  public:
    Validator(const std::string& origin, const KeyLines& lines) : origin_(origin), lines_(lines) {}

    [[noreturn]] void fail(const std::string& key, const std::string& problem) const
    {
        // A key inside a matrix or map points at its parent when it has no line of its own.
        std::string probe = key;
        int line = 0;
        while (!probe.empty()) {
            const auto it = lines_.find(probe);
            if (it != lines_.end()) {
                line = it->second;
                break;
            }
            const auto dot = probe.rfind('.');
            probe = dot == std::string::npos ? std::string() : probe.substr(0, dot);
        }
        calibration_detail::fail(origin_, line, key, problem);
    }

    void finite(const std::string& key, double value) const
    {
        if (!std::isfinite(value))
            fail(key, "must be a finite number, got " + formatNumber(value));
    }

    void positive(const std::string& key, double value) const
    {
        finite(key, value);
        if (value <= 0.0)
            fail(key, "must be > 0, got " + formatNumber(value));
    }

    void nonNegative(const std::string& key, double value) const
    {
        finite(key, value);
        if (value < 0.0)
            fail(key, "must be >= 0, got " + formatNumber(value));
    }

    template <int R, int C>
    void allFinite(const std::string& key, const cv::Matx<double, R, C>& m) const
    {
        for (int r = 0; r < R; ++r)
            for (int c = 0; c < C; ++c)
                if (!std::isfinite(m(r, c)))
                    fail(key, "element (" + std::to_string(r) + "," + std::to_string(c) +
                                  ") is not a finite number");
    }

    void imageSize(cv::Size size) const
    {
        if (size.width <= 0 || size.height <= 0)
            fail("image_size", "width and height must be > 0, got " + describeSize(size));
    }

    void principalPoint(const std::string& key, double cx, double cy, cv::Size size) const
    {
        finite(key, cx);
        finite(key, cy);
        if (cx < 0.0 || cx >= size.width || cy < 0.0 || cy >= size.height)
            fail(key, "principal point (" + formatNumber(cx) + ", " + formatNumber(cy) +
                          ") lies outside the " + describeSize(size) + " image");
    }

    void rotation(const std::string& key, const cv::Matx33d& r) const
    {
        allFinite(key, r);
        const cv::Matx33d should_be_identity = r.t() * r;
        double worst = 0.0;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                worst = std::max(worst, std::abs(should_be_identity(i, j) - (i == j ? 1.0 : 0.0)));
        if (worst > kRotationTolerance)
            fail(key, "not a rotation matrix: R^T R differs from the identity by " +
                          formatNumber(worst));
        const double det = cv::determinant(r);
        if (std::abs(det - 1.0) > kRotationTolerance)
            fail(key, "not a rotation matrix: determinant " + formatNumber(det) +
                          " (a reflection has -1)");
    }

    void cameraMatrix(const std::string& key, const cv::Matx33d& k, cv::Size size) const
    {
        allFinite(key, k);
        if (k(0, 0) <= 0.0)
            fail(key, "focal length fx (element 0,0) must be > 0, got " + formatNumber(k(0, 0)));
        if (k(1, 1) <= 0.0)
            fail(key, "focal length fy (element 1,1) must be > 0, got " + formatNumber(k(1, 1)));
        if (k(1, 0) != 0.0 || k(2, 0) != 0.0 || k(2, 1) != 0.0 || k(2, 2) != 1.0)
            fail(key, "expected the form [fx s cx; 0 fy cy; 0 0 1]");
        principalPoint(key, k(0, 2), k(1, 2), size);
    }

    void distortion(const std::string& key, const std::vector<double>& d) const
    {
        const size_t n = d.size();
        if (n != 0 && n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
            fail(key, "expected 0, 4, 5, 8, 12 or 14 coefficients (OpenCV's models), got " +
                          std::to_string(n));
        for (size_t i = 0; i < n; ++i)
            if (!std::isfinite(d[i]))
                fail(key, "coefficient " + std::to_string(i) + " is not a finite number");
    }

    void roi(const std::string& key, const cv::Rect& rect, cv::Size size) const
    {
        if (rect.x < 0 || rect.y < 0 || rect.width < 0 || rect.height < 0 ||
            rect.x + rect.width > size.width || rect.y + rect.height > size.height)
            fail(key, "rectangle x=" + std::to_string(rect.x) + " y=" + std::to_string(rect.y) +
                          " " + std::to_string(rect.width) + "x" + std::to_string(rect.height) +
                          " does not lie inside the " + describeSize(size) + " image");
    }

    void geometry(const RectifiedGeometry& g, bool full) const
    {
        // In the full form these numbers come from P1/P2: point there.
        imageSize(toCv(g.image_size));
        positive(full ? "P1" : "focal_px", g.focal_px);
        positive(full ? "P2" : "baseline_m", g.baseline_m);
        finite(full ? "P2" : "doffs_px", g.doffs_px);
        if (full) {
            principalPoint("P1", g.cx_px, g.cy_px, toCv(g.image_size));
        } else {
            // Separate keys in the rectified form: name the one that is wrong.
            finite("cx_px", g.cx_px);
            finite("cy_px", g.cy_px);
            if (g.cx_px < 0.0 || g.cx_px >= g.image_size.width)
                fail("cx_px", formatNumber(g.cx_px) + " lies outside the image (width " +
                                  std::to_string(g.image_size.width) + ")");
            if (g.cy_px < 0.0 || g.cy_px >= g.image_size.height)
                fail("cy_px", formatNumber(g.cy_px) + " lies outside the image (height " +
                                  std::to_string(g.image_size.height) + ")");
        }
    }

    void full(const StereoCalibration& c) const
    {
        const cv::Size size = toCv(c.rectified.image_size);
        imageSize(size);
        cameraMatrix("left.camera_matrix", c.left.camera_matrix, size);
        distortion("left.distortion", c.left.distortion);
        cameraMatrix("right.camera_matrix", c.right.camera_matrix, size);
        distortion("right.distortion", c.right.distortion);
        rotation("R", c.R);
        for (int i = 0; i < 3; ++i)
            finite("T", c.T[i]);
        const double t_norm = cv::norm(c.T);
        if (t_norm <= 0.0)
            fail("T", "the translation between the cameras must not be zero");
        rotation("R1", c.R1);
        rotation("R2", c.R2);
        allFinite("P1", c.P1);
        allFinite("P2", c.P2);
        allFinite("Q", c.Q);
        if (c.P1(0, 0) <= 0.0 || c.P1(1, 1) <= 0.0)
            fail("P1", "focal length (elements 0,0 and 1,1) must be > 0, got " +
                           formatNumber(c.P1(0, 0)) + " and " + formatNumber(c.P1(1, 1)));
        if (c.P1(0, 3) != 0.0 || c.P1(1, 3) != 0.0)
            fail("P1", "the left projection must have no translation (column 3 zero)");
        if (c.P2(0, 0) != c.P1(0, 0) || c.P2(1, 1) != c.P1(1, 1) || c.P2(1, 2) != c.P1(1, 2))
            fail("P2", "focal length and cy must equal those of P1 (one rectified camera)");
        if (c.P2(1, 3) != 0.0)
            fail("P2", "element (1,3) is not zero: a vertical rig, only horizontal rigs are "
                       "supported");
        if (c.P2(0, 3) >= 0.0)
            fail("P2", "element (0,3) = -focal * baseline must be < 0 (the right camera on "
                       "the right), got " +
                           formatNumber(c.P2(0, 3)));
        const RectifiedGeometry derived = rectifiedFromProjections(c.P1, c.P2, size);
        geometry(derived, true);
        if (std::abs(derived.baseline_m - t_norm) > kConsistencyTolerance * t_norm)
            fail("P2", "baseline " + formatNumber(derived.baseline_m) + " m disagrees with |T| = " +
                           formatNumber(t_norm) + " m (same unit expected in both)");
        if (std::abs(c.Q(2, 3) - derived.focal_px) > kConsistencyTolerance * derived.focal_px)
            fail("Q", "element (2,3) " + formatNumber(c.Q(2, 3)) +
                          " should be the focal length of P1, " + formatNumber(derived.focal_px));
        const double inv_b = 1.0 / derived.baseline_m;
        if (std::abs(c.Q(3, 2) - inv_b) > kConsistencyTolerance * inv_b)
            fail("Q", "element (3,2) " + formatNumber(c.Q(3, 2)) + " should be 1/baseline, " +
                          formatNumber(inv_b));
        if (c.rectified.focal_px != derived.focal_px || c.rectified.cx_px != derived.cx_px ||
            c.rectified.cy_px != derived.cy_px || c.rectified.baseline_m != derived.baseline_m ||
            c.rectified.doffs_px != derived.doffs_px)
            fail("rectified", "the rectified geometry must be the one P1 and P2 imply "
                              "(use rectifiedFromProjections)");
        roi("valid_roi_left", c.valid_roi_left, size);
        roi("valid_roi_right", c.valid_roi_right, size);
        if (c.rms_px)
            nonNegative("rms_px", *c.rms_px);
        if (c.epipolar_error_px)
            nonNegative("epipolar_error_px", *c.epipolar_error_px);
        if (c.board) {
            if (c.board->cols < 2 || c.board->rows < 2)
                fail("board", "cols and rows (inner corners) must be >= 2, got " +
                                  std::to_string(c.board->cols) + "x" +
                                  std::to_string(c.board->rows));
            positive("board.square_m", c.board->square_m);
        }
    }

    void any(const StereoCalibration& c) const
    {
        if (c.kind == StereoCalibration::Kind::Full)
            full(c);
        else
            geometry(c.rectified, false);
    }

  private:
    const std::string& origin_;
    const KeyLines& lines_;
};

} // namespace

void checkCalibration(const StereoCalibration& calibration, const std::string& origin,
                      const KeyLines& lines)
{
    Validator(origin, lines).any(calibration);
}

} // namespace stereod::calibration_detail

namespace stereod {

void validateCalibration(const StereoCalibration& calibration, const std::string& origin)
{
    calibration_detail::checkCalibration(calibration, origin, calibration_detail::KeyLines{});
}

} // namespace stereod
