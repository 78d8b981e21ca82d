#include "pipeline/calibration.hpp"

#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <initializer_list>
#include <map>
#include <sstream>

#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

namespace stereod {

void throwCalibrationError(const std::string& origin, int line, const std::string& key,
                           const std::string& problem)
{
    std::string message = origin;
    if (line > 0)
        message += ":" + std::to_string(line);
    message += ": ";
    if (!key.empty())
        message += key + ": ";
    message += problem;
    throw CalibrationError(message);
}

namespace {

constexpr int kFormatVersion = 1;
// Tolerance on R^T R = I and det R = 1: the files carry 17 significant digits, a person
// editing one by hand may round to 6.
constexpr double kRotationTolerance = 1e-5;
// Relative tolerance for quantities that appear twice in a full calibration (P2 vs |T|,
// Q vs P1/P2): they must agree, but need not be bit-identical.
constexpr double kConsistencyTolerance = 1e-2;

// Line (1-based) of each key seen while parsing, so that validation after parsing can
// still point at the place in the file.
using KeyLines = std::map<std::string, int>;

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
        stereod::fail(origin_, line, key, problem);
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
        imageSize(g.image_size);
        positive(full ? "P1" : "focal_px", g.focal_px);
        positive(full ? "P2" : "baseline_m", g.baseline_m);
        finite(full ? "P2" : "doffs_px", g.doffs_px);
        if (full) {
            principalPoint("P1", g.cx_px, g.cy_px, g.image_size);
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
        const cv::Size size = c.rectified.image_size;
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

// ---------------------------------------------------------------------------------------
// Parsing.

class Parser {
  public:
    explicit Parser(const std::string& origin) : origin_(origin) {}

    const KeyLines& lines() const { return lines_; }

    // A scalar is reported at its own line; a mapping or sequence at the line of its key
    // (its value may start on the next line).
    [[noreturn]] void fail(const YAML::Node& at, const std::string& key,
                           const std::string& problem) const
    {
        int line = at.IsDefined() && at.IsScalar() ? lineOf(at) : 0;
        if (line == 0) {
            const auto it = lines_.find(key);
            line = it != lines_.end() ? it->second : lineOf(at);
        }
        stereod::fail(origin_, line, key, problem);
    }

    static int lineOf(const YAML::Node& node)
    {
        if (!node.IsDefined())
            return 0;
        const YAML::Mark mark = node.Mark();
        return mark.is_null() ? 0 : mark.line + 1;
    }

    static std::string join(const std::string& parent, const std::string& key)
    {
        return parent.empty() ? key : parent + "." + key;
    }

    void expectMap(const YAML::Node& node, const std::string& key) const
    {
        if (!node.IsMap())
            fail(node, key, "expected a mapping of keys to values");
    }

    // Rejects keys the format does not know: a misspelt optional key (say "doffs" for
    // "doffs_px") would otherwise be ignored silently and give wrong depths.
    void onlyKeys(const YAML::Node& map, const std::string& key,
                  std::initializer_list<const char*> allowed) const
    {
        for (const auto& entry : map) {
            const std::string name = entry.first.Scalar();
            bool known = false;
            for (const char* a : allowed)
                known = known || name == a;
            if (!known)
                fail(entry.first, join(key, name), "unknown key");
        }
    }

    // The line of `key` itself (not of its value, which may start on the next line).
    static int keyLine(const YAML::Node& map, const char* key)
    {
        for (const auto& entry : map)
            if (entry.first.IsScalar() && entry.first.Scalar() == key)
                return lineOf(entry.first);
        return 0;
    }

    YAML::Node optional(const YAML::Node& map, const std::string& parent, const char* key)
    {
        const YAML::Node node = map[key];
        if (!node.IsDefined() || node.IsNull())
            return YAML::Node(YAML::NodeType::Undefined);
        lines_[join(parent, key)] = keyLine(map, key);
        return node;
    }

    YAML::Node require(const YAML::Node& map, const std::string& parent, const char* key)
    {
        YAML::Node node = optional(map, parent, key);
        if (!node.IsDefined()) {
            // Point at the enclosing key; a missing top-level key has no line to show.
            const auto it = lines_.find(parent);
            stereod::fail(origin_, it != lines_.end() ? it->second : 0, join(parent, key),
                          "missing key");
        }
        return node;
    }

    double number(const YAML::Node& node, const std::string& key) const
    {
        if (!node.IsScalar())
            fail(node, key, "expected a number");
        double value = 0.0;
        try {
            value = node.as<double>();
        } catch (const YAML::Exception&) {
            fail(node, key, "not a number: '" + node.Scalar() + "'");
        }
        if (!std::isfinite(value))
            fail(node, key, "must be a finite number, got '" + node.Scalar() + "'");
        return value;
    }

    int integer(const YAML::Node& node, const std::string& key) const
    {
        if (!node.IsScalar())
            fail(node, key, "expected an integer");
        try {
            return node.as<int>();
        } catch (const YAML::Exception&) {
            fail(node, key, "not an integer: '" + node.Scalar() + "'");
        }
    }

    double requireNumber(const YAML::Node& map, const std::string& parent, const char* key)
    {
        return number(require(map, parent, key), join(parent, key));
    }

    int requireInteger(const YAML::Node& map, const std::string& parent, const char* key)
    {
        return integer(require(map, parent, key), join(parent, key));
    }

    std::vector<double> numbers(const YAML::Node& node, const std::string& key) const
    {
        if (!node.IsSequence())
            fail(node, key, "expected a sequence of numbers [a, b, ...]");
        std::vector<double> values;
        values.reserve(node.size());
        for (size_t i = 0; i < node.size(); ++i)
            values.push_back(number(node[i], key + "[" + std::to_string(i) + "]"));
        return values;
    }

    // {rows: R, cols: C, data: [row-major values]}
    template <int R, int C>
    cv::Matx<double, R, C> matrix(const YAML::Node& map, const std::string& parent,
                                  const char* name)
    {
        const std::string key = join(parent, name);
        const YAML::Node node = require(map, parent, name);
        expectMap(node, key);
        onlyKeys(node, key, {"rows", "cols", "data"});
        const int rows = requireInteger(node, key, "rows");
        const int cols = requireInteger(node, key, "cols");
        if (rows != R || cols != C)
            fail(node, key,
                 "expected a " + std::to_string(R) + "x" + std::to_string(C) +
                     " matrix, got rows " + std::to_string(rows) + " cols " + std::to_string(cols));
        const YAML::Node data_node = require(node, key, "data");
        const std::vector<double> data = numbers(data_node, key + ".data");
        if (data.size() != static_cast<size_t>(R * C))
            fail(data_node, key + ".data",
                 "expected " + std::to_string(R * C) + " values (" + std::to_string(R) + "x" +
                     std::to_string(C) + "), got " + std::to_string(data.size()));
        cv::Matx<double, R, C> m;
        for (int i = 0; i < R * C; ++i)
            m.val[i] = data[static_cast<size_t>(i)];
        return m;
    }

    cv::Size imageSize(const YAML::Node& root)
    {
        const YAML::Node node = require(root, "", "image_size");
        expectMap(node, "image_size");
        onlyKeys(node, "image_size", {"width", "height"});
        return {requireInteger(node, "image_size", "width"),
                requireInteger(node, "image_size", "height")};
    }

    CameraIntrinsics camera(const YAML::Node& root, const char* side)
    {
        const YAML::Node node = require(root, "", side);
        expectMap(node, side);
        onlyKeys(node, side, {"camera_matrix", "distortion"});
        CameraIntrinsics intrinsics;
        intrinsics.camera_matrix = matrix<3, 3>(node, side, "camera_matrix");
        const std::string dkey = join(side, "distortion");
        intrinsics.distortion = numbers(require(node, side, "distortion"), dkey);
        return intrinsics;
    }

    cv::Rect roi(const YAML::Node& root, const char* key)
    {
        const YAML::Node node = optional(root, "", key);
        if (!node.IsDefined())
            return {};
        expectMap(node, key);
        onlyKeys(node, key, {"x", "y", "width", "height"});
        return {requireInteger(node, key, "x"), requireInteger(node, key, "y"),
                requireInteger(node, key, "width"), requireInteger(node, key, "height")};
    }

    std::optional<double> optionalNumber(const YAML::Node& root, const char* key)
    {
        const YAML::Node node = optional(root, "", key);
        if (!node.IsDefined())
            return std::nullopt;
        return number(node, key);
    }

    StereoCalibration full(const YAML::Node& root)
    {
        onlyKeys(root, "",
                 {"stereod_calibration", "kind", "image_size", "left", "right", "R", "T", "R1",
                  "R2", "P1", "P2", "Q", "valid_roi_left", "valid_roi_right", "rms_px",
                  "epipolar_error_px", "board"});
        StereoCalibration c;
        c.kind = StereoCalibration::Kind::Full;
        const cv::Size size = imageSize(root);
        c.left = camera(root, "left");
        c.right = camera(root, "right");
        c.R = matrix<3, 3>(root, "", "R");
        const YAML::Node t_node = require(root, "", "T");
        const std::vector<double> t = numbers(t_node, "T");
        if (t.size() != 3)
            fail(t_node, "T", "expected 3 values [tx, ty, tz], got " + std::to_string(t.size()));
        c.T = cv::Vec3d(t[0], t[1], t[2]);
        c.R1 = matrix<3, 3>(root, "", "R1");
        c.R2 = matrix<3, 3>(root, "", "R2");
        c.P1 = matrix<3, 4>(root, "", "P1");
        c.P2 = matrix<3, 4>(root, "", "P2");
        c.Q = matrix<4, 4>(root, "", "Q");
        c.valid_roi_left = roi(root, "valid_roi_left");
        c.valid_roi_right = roi(root, "valid_roi_right");
        c.rms_px = optionalNumber(root, "rms_px");
        c.epipolar_error_px = optionalNumber(root, "epipolar_error_px");
        const YAML::Node board = optional(root, "", "board");
        if (board.IsDefined()) {
            expectMap(board, "board");
            onlyKeys(board, "board", {"cols", "rows", "square_m"});
            ChessboardSpec spec;
            spec.cols = requireInteger(board, "board", "cols");
            spec.rows = requireInteger(board, "board", "rows");
            spec.square_m = requireNumber(board, "board", "square_m");
            c.board = spec;
        }
        c.rectified = rectifiedFromProjections(c.P1, c.P2, size);
        return c;
    }

    StereoCalibration rectified(const YAML::Node& root)
    {
        onlyKeys(root, "",
                 {"stereod_calibration", "kind", "image_size", "focal_px", "cx_px", "cy_px",
                  "baseline_m", "doffs_px"});
        StereoCalibration c;
        c.kind = StereoCalibration::Kind::RectifiedOnly;
        RectifiedGeometry& g = c.rectified;
        g.image_size = imageSize(root);
        g.focal_px = requireNumber(root, "", "focal_px");
        g.baseline_m = requireNumber(root, "", "baseline_m");
        g.cx_px = optionalNumber(root, "cx_px").value_or((g.image_size.width - 1) / 2.0);
        g.cy_px = optionalNumber(root, "cy_px").value_or((g.image_size.height - 1) / 2.0);
        g.doffs_px = optionalNumber(root, "doffs_px").value_or(0.0);
        return c;
    }

    StereoCalibration parse(const YAML::Node& root)
    {
        if (!root.IsMap())
            fail(root, "", "expected a mapping at the top level (see docs/calibration.md)");
        const YAML::Node version = require(root, "", "stereod_calibration");
        const int v = integer(version, "stereod_calibration");
        if (v != kFormatVersion)
            fail(version, "stereod_calibration",
                 "unsupported format version " + std::to_string(v) + " (this build reads " +
                     std::to_string(kFormatVersion) + ")");
        const YAML::Node kind = require(root, "", "kind");
        const std::string kind_text = kind.IsScalar() ? kind.Scalar() : std::string();
        if (kind_text == "full")
            return full(root);
        if (kind_text == "rectified")
            return rectified(root);
        fail(kind, "kind", "expected 'full' or 'rectified', got '" + kind_text + "'");
    }

  private:
    const std::string& origin_;
    KeyLines lines_;
};

// ---------------------------------------------------------------------------------------
// Writing.

class Writer {
  public:
    std::string text() const { return out_.str(); }

    void line(const std::string& s) { out_ << s << '\n'; }

    void numberList(const std::string& indent, const std::string& key, const double* values,
                    size_t n)
    {
        out_ << indent << key << ": [";
        for (size_t i = 0; i < n; ++i)
            out_ << (i ? ", " : "") << formatNumber(values[i]);
        out_ << "]\n";
    }

    template <int R, int C>
    void matrix(const std::string& indent, const std::string& key, const cv::Matx<double, R, C>& m)
    {
        out_ << indent << key << ":\n";
        out_ << indent << "  rows: " << R << "\n";
        out_ << indent << "  cols: " << C << "\n";
        // One matrix row per line: a flow sequence may span lines.
        const std::string lead = indent + "  data: [";
        const std::string cont(lead.size(), ' ');
        for (int r = 0; r < R; ++r) {
            out_ << (r == 0 ? lead : cont);
            for (int c = 0; c < C; ++c) {
                out_ << formatNumber(m(r, c));
                if (c + 1 < C)
                    out_ << ", ";
                else if (r + 1 < R)
                    out_ << ",";
            }
            out_ << (r + 1 < R ? "\n" : "]\n");
        }
    }

    void camera(const char* side, const CameraIntrinsics& intrinsics)
    {
        line(std::string(side) + ":");
        matrix("  ", "camera_matrix", intrinsics.camera_matrix);
        numberList("  ", "distortion", intrinsics.distortion.data(), intrinsics.distortion.size());
    }

    void roi(const char* key, const cv::Rect& rect)
    {
        if (rect.width <= 0 && rect.height <= 0 && rect.x == 0 && rect.y == 0)
            return;
        out_ << key << ": {x: " << rect.x << ", y: " << rect.y << ", width: " << rect.width
             << ", height: " << rect.height << "}\n";
    }

    void write(const StereoCalibration& c)
    {
        const RectifiedGeometry& g = c.rectified;
        line("# stereod stereo calibration, format described in docs/calibration.md");
        line("stereod_calibration: " + std::to_string(kFormatVersion));
        if (c.kind == StereoCalibration::Kind::RectifiedOnly) {
            line("kind: rectified");
            line("image_size: {width: " + std::to_string(g.image_size.width) +
                 ", height: " + std::to_string(g.image_size.height) + "}");
            line("focal_px: " + formatNumber(g.focal_px));
            line("cx_px: " + formatNumber(g.cx_px));
            line("cy_px: " + formatNumber(g.cy_px));
            line("baseline_m: " + formatNumber(g.baseline_m));
            line("doffs_px: " + formatNumber(g.doffs_px));
            return;
        }
        line("kind: full");
        line("# rectified geometry implied by P1/P2: focal_px " + formatNumber(g.focal_px) +
             ", cx_px " + formatNumber(g.cx_px) + ", cy_px " + formatNumber(g.cy_px) +
             ", baseline_m " + formatNumber(g.baseline_m) + ", doffs_px " +
             formatNumber(g.doffs_px));
        line("image_size: {width: " + std::to_string(g.image_size.width) +
             ", height: " + std::to_string(g.image_size.height) + "}");
        camera("left", c.left);
        camera("right", c.right);
        matrix("", "R", c.R);
        numberList("", "T", c.T.val, 3);
        matrix("", "R1", c.R1);
        matrix("", "R2", c.R2);
        matrix("", "P1", c.P1);
        matrix("", "P2", c.P2);
        matrix("", "Q", c.Q);
        roi("valid_roi_left", c.valid_roi_left);
        roi("valid_roi_right", c.valid_roi_right);
        if (c.rms_px)
            line("rms_px: " + formatNumber(*c.rms_px));
        if (c.epipolar_error_px)
            line("epipolar_error_px: " + formatNumber(*c.epipolar_error_px));
        if (c.board)
            line("board: {cols: " + std::to_string(c.board->cols) +
                 ", rows: " + std::to_string(c.board->rows) +
                 ", square_m: " + formatNumber(c.board->square_m) + "}");
    }

  private:
    std::ostringstream out_;
};

std::string errnoText(int error)
{
    return std::strerror(error);
}

} // namespace

RectifiedGeometry rectifiedFromProjections(const cv::Matx34d& P1, const cv::Matx34d& P2,
                                           cv::Size image_size)
{
    RectifiedGeometry g;
    g.image_size = image_size;
    g.focal_px = P1(0, 0);
    g.cx_px = P1(0, 2);
    g.cy_px = P1(1, 2);
    g.baseline_m = P2(0, 0) != 0.0 ? -P2(0, 3) / P2(0, 0) : 0.0;
    g.doffs_px = P2(0, 2) - P1(0, 2);
    return g;
}

void validateCalibration(const StereoCalibration& calibration, const std::string& origin)
{
    const KeyLines no_lines;
    Validator(origin, no_lines).any(calibration);
}

StereoCalibration parseCalibration(const std::string& yaml_text, const std::string& origin)
{
    // OpenCV's FileStorage writes "%YAML:1.0", which is not YAML 1.2: say what it is.
    if (yaml_text.rfind("%YAML:1.0", 0) == 0)
        fail(origin, 1, "",
             "this is an OpenCV FileStorage file, not a stereod calibration; "
             "convert it to the layout in docs/calibration.md");
    YAML::Node root;
    try {
        root = YAML::Load(yaml_text);
    } catch (const YAML::Exception& e) {
        fail(origin, e.mark.is_null() ? 0 : e.mark.line + 1, "", "invalid YAML: " + e.msg);
    }
    if (!root.IsDefined() || root.IsNull())
        fail(origin, 0, "", "the file is empty");
    Parser parser(origin);
    StereoCalibration calibration;
    try {
        calibration = parser.parse(root);
    } catch (const YAML::Exception& e) {
        // Anything the parser did not anticipate still names the place.
        fail(origin, e.mark.is_null() ? 0 : e.mark.line + 1, "", e.msg);
    }
    Validator(origin, parser.lines()).any(calibration);
    return calibration;
}

StereoCalibration loadCalibration(const std::string& path)
{
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        const int error = errno;
        fail(path, 0, "", "cannot open: " + errnoText(error));
    }
    std::ostringstream text;
    text << in.rdbuf();
    if (in.bad()) {
        const int error = errno;
        fail(path, 0, "", "cannot read: " + errnoText(error));
    }
    return parseCalibration(text.str(), path);
}

std::string formatCalibration(const StereoCalibration& calibration, const std::string& origin)
{
    validateCalibration(calibration, origin);
    Writer writer;
    writer.write(calibration);
    return writer.text();
}

void saveCalibration(const StereoCalibration& calibration, const std::string& path)
{
    validateCalibration(calibration, path);
    Writer writer;
    writer.write(calibration);
    const std::string text = writer.text();

    // Temporary file in the target's directory, so that rename() is atomic: a reader sees
    // the old file or the new one, never half of one.
    std::string temp = path + ".tmp.XXXXXX";
    const int fd = ::mkstemp(temp.data());
    if (fd < 0) {
        const int error = errno;
        fail(path, 0, "", "cannot create temporary file " + temp + ": " + errnoText(error));
    }
    const auto give_up = [&](const std::string& what) {
        const int error = errno;
        ::close(fd);
        ::unlink(temp.c_str());
        fail(path, 0, "", what + ": " + errnoText(error));
    };
    size_t written = 0;
    while (written < text.size()) {
        const ssize_t n = ::write(fd, text.data() + written, text.size() - written);
        if (n < 0) {
            if (errno == EINTR)
                continue;
            give_up("cannot write " + temp);
        }
        written += static_cast<size_t>(n);
    }
    // mkstemp creates the file 0600; a calibration is not secret and the service may run
    // as another user.
    if (::fchmod(fd, 0644) != 0)
        give_up("cannot set the mode of " + temp);
    if (::fsync(fd) != 0)
        give_up("cannot flush " + temp);
    if (::close(fd) != 0) {
        const int error = errno;
        ::unlink(temp.c_str());
        fail(path, 0, "", "cannot close " + temp + ": " + errnoText(error));
    }
    if (std::rename(temp.c_str(), path.c_str()) != 0) {
        const int error = errno;
        ::unlink(temp.c_str());
        fail(path, 0, "", "cannot rename " + temp + " to it: " + errnoText(error));
    }
}

void checkFrameSize(const StereoCalibration& calibration, cv::Size frame_size,
                    const std::string& origin)
{
    const cv::Size expected = calibration.rectified.image_size;
    if (frame_size != expected)
        fail(origin, 0, "image_size",
             "frames are " + describeSize(frame_size) + " but the calibration is for " +
                 describeSize(expected) + " images");
}

StereoCalibration makeRectifiedCalibration(cv::Size image_size, double focal_px, double baseline_m,
                                           std::optional<double> cx_px, std::optional<double> cy_px,
                                           double doffs_px)
{
    StereoCalibration c;
    c.kind = StereoCalibration::Kind::RectifiedOnly;
    c.rectified.image_size = image_size;
    c.rectified.focal_px = focal_px;
    c.rectified.baseline_m = baseline_m;
    c.rectified.cx_px = cx_px.value_or((image_size.width - 1) / 2.0);
    c.rectified.cy_px = cy_px.value_or((image_size.height - 1) / 2.0);
    c.rectified.doffs_px = doffs_px;
    validateCalibration(c, "rectified calibration");
    return c;
}

} // namespace stereod
