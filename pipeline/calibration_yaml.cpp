// The calibration's YAML file: parsing with each key's line kept for messages, and
// writing that reads back to the same doubles, replacing the file atomically.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include "base/system_error.hpp"
#include "pipeline/calibration.hpp"
#include "pipeline/calibration_checks.hpp"
#include "pipeline/cv_conversions.hpp"

namespace stereod {

using namespace calibration_detail;

namespace {

constexpr int kFormatVersion = 1;

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
        calibration_detail::fail(origin_, line, key, problem);
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
            calibration_detail::fail(origin_, it != lines_.end() ? it->second : 0,
                                     join(parent, key), "missing key");
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
        g.image_size = toImageSize(imageSize(root));
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

} // namespace

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
    checkCalibration(calibration, origin, parser.lines());
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

} // namespace stereod
