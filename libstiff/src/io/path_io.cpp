// Machining path readers: CSV of tool poses and a G-code subset (path_io.hpp).
#include "stiff/io/path_io.hpp"

#include <Eigen/Geometry>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <map>
#include <sstream>

#include "stiff/error.hpp"
#include "stiff/io/text_io.hpp"

namespace stiff {
namespace {

constexpr double kPi = 3.141592653589793238462643383279502884;

// Largest distance of an arc's chords from the circle [m]: well below the repeatability of
// industrial robots (~20 um), so the linearised path is the programmed one.
constexpr double kArcChordTolerance = 1e-6;
constexpr double kPiPath = 3.141592653589793238462643383279502884;

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> lines;
  std::string cur;
  // A UTF-8 byte-order mark (written by some CAM post-processors and Windows editors).
  const size_t skip = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
  for (size_t n = skip; n < text.size(); ++n) {
    const char ch = text[n];
    if (ch == '\n') {
      if (!cur.empty() && cur.back() == '\r') cur.pop_back();
      lines.push_back(cur);
      cur.clear();
    } else {
      cur += ch;
    }
  }
  if (!cur.empty()) {
    if (cur.back() == '\r') cur.pop_back();
    lines.push_back(cur);
  }
  return lines;
}

struct Field {
  std::string text;
  int col;
};

std::vector<Field> split_csv(const std::string& line) {
  std::vector<Field> out;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    std::string t =
        line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    size_t b = t.find_first_not_of(" \t");
    const size_t e = t.find_last_not_of(" \t");
    const int col = static_cast<int>(start + (b == std::string::npos ? 0 : b)) + 1;
    t = b == std::string::npos ? std::string() : t.substr(b, e - b + 1);
    out.push_back({t, col});
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

bool parse_double(const std::string& s, double* v) {
  if (s.empty()) return false;
  const char* begin = s.c_str();
  char* end = nullptr;
  *v = std::strtod(begin, &end);
  return end == begin + s.size() && std::isfinite(*v);
}

bool blank_or_comment(const std::string& line) {
  const size_t b = line.find_first_not_of(" \t");
  return b == std::string::npos || line[b] == '#';
}

// Column kinds of a path CSV.
enum class Kind { x, rpy, quat, force, moment, feed, id, ignored };
struct Column {
  Kind kind = Kind::ignored;
  int index = 0;
  double scale = 1.0;
};

Column classify(const std::string& name, const std::string& file, int line, int col) {
  struct Base {
    const char* base;
    Kind kind;
    int index;
  };
  static const Base bases[] = {
      {"x", Kind::x, 0},       {"y", Kind::x, 1},       {"z", Kind::x, 2},
      {"rx", Kind::rpy, 0},    {"ry", Kind::rpy, 1},    {"rz", Kind::rpy, 2},
      {"fx", Kind::force, 0},  {"fy", Kind::force, 1},  {"fz", Kind::force, 2},
      {"mx", Kind::moment, 0}, {"my", Kind::moment, 1}, {"mz", Kind::moment, 2}};
  Column c;
  if (name == "id") return {Kind::id, 0, 1.0};
  static const char* quat[] = {"qw", "qx", "qy", "qz"};
  for (int k = 0; k < 4; ++k)
    if (name == quat[k]) return {Kind::quat, k, 1.0};
  if (name == "feed_mm_min") return {Kind::feed, 0, 1e-3 / 60.0};
  if (name == "feed_m_s") return {Kind::feed, 0, 1.0};
  if (name == "feed_m_min") return {Kind::feed, 0, 1.0 / 60.0};
  for (const Base& b : bases) {
    const std::string base = b.base;
    if (name == base)
      throw ParseError(file, line, col,
                       "column '" + name + "' has no unit suffix (e.g. " + base +
                           (b.kind == Kind::x       ? "_mm"
                            : b.kind == Kind::rpy   ? "_deg"
                            : b.kind == Kind::force ? "_N"
                                                    : "_Nm") +
                           ")");
    if (name.compare(0, base.size() + 1, base + "_") != 0) continue;
    const std::string unit = name.substr(base.size() + 1);
    static const std::map<std::string, double> length{{"m", 1.0}, {"mm", 1e-3}, {"um", 1e-6}};
    static const std::map<std::string, double> angle{{"rad", 1.0}, {"deg", kPi / 180.0}};
    static const std::map<std::string, double> force{{"N", 1.0}};
    static const std::map<std::string, double> moment{{"Nm", 1.0}, {"Nmm", 1e-3}};
    const std::map<std::string, double>& table = b.kind == Kind::x       ? length
                                                 : b.kind == Kind::rpy   ? angle
                                                 : b.kind == Kind::force ? force
                                                                         : moment;
    const auto it = table.find(unit);
    if (it == table.end()) {
      std::string accepted;
      for (const auto& kv : table) accepted += (accepted.empty() ? "_" : ", _") + kv.first;
      throw ParseError(
          file, line, col,
          "column '" + name + "': unknown unit '" + unit + "' (accepted: " + accepted + ")");
    }
    return {b.kind, b.index, it->second};
  }
  return c;  // ignored
}

Eigen::Matrix4d frame_pose(const PathOptions& o,
                           const Eigen::Vector3d& p,
                           const Eigen::Matrix3d& r) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.block<3, 3>(0, 0) = r;
  t.block<3, 1>(0, 3) = p;
  return o.frame * t;
}

void check_options(const PathOptions& o, const std::string& file) {
  if (!o.frame.allFinite() || !o.tool_orientation.allFinite())
    throw InvalidArgument(file + ": the workpiece frame or tool orientation is not finite");
  const Eigen::Matrix3d r = o.frame.block<3, 3>(0, 0);
  if ((r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
      (o.tool_orientation.transpose() * o.tool_orientation - Eigen::Matrix3d::Identity()).norm() >
          1e-6)
    throw InvalidArgument(file + ": the workpiece frame or tool orientation is not a rotation");
  if (!(o.segment_m >= 0))
    throw InvalidArgument(file + ": the segment length segment_m must be >= 0 [m] (got " +
                          std::to_string(o.segment_m) + ")");
}

}  // namespace

std::vector<Eigen::Matrix4d> ToolPath::poses() const {
  std::vector<Eigen::Matrix4d> out;
  out.reserve(points.size());
  for (const auto& p : points) out.push_back(p.pose);
  return out;
}

Eigen::MatrixXd ToolPath::wrenches() const {
  Eigen::MatrixXd w(static_cast<Eigen::Index>(points.size()), 6);
  for (size_t i = 0; i < points.size(); ++i)
    w.row(static_cast<Eigen::Index>(i)) = points[i].wrench.transpose();
  return w;
}

Eigen::Matrix4d pose_from_xyz_rpy(const Eigen::Matrix<double, 6, 1>& v) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  t.block<3, 3>(0, 0) = (Eigen::AngleAxisd(v(5), Eigen::Vector3d::UnitZ()) *
                         Eigen::AngleAxisd(v(4), Eigen::Vector3d::UnitY()) *
                         Eigen::AngleAxisd(v(3), Eigen::Vector3d::UnitX()))
                            .toRotationMatrix();
  t.block<3, 1>(0, 3) = v.head<3>();
  return t;
}

Eigen::Matrix<double, 6, 1> xyz_rpy_from_pose(const Eigen::Matrix4d& t) {
  const Eigen::Matrix3d r = t.block<3, 3>(0, 0);
  Eigen::Matrix<double, 6, 1> v;
  v.head<3>() = t.block<3, 1>(0, 3);
  const double ry = std::atan2(-r(2, 0), std::hypot(r(0, 0), r(1, 0)));
  double rx, rz;
  if (std::hypot(r(0, 0), r(1, 0)) < 1e-12) {  // gimbal lock: put everything in rz
    rx = 0.0;
    rz = std::atan2(-r(0, 1), r(1, 1));
  } else {
    rx = std::atan2(r(2, 1), r(2, 2));
    rz = std::atan2(r(1, 0), r(0, 0));
  }
  v(3) = rx;
  v(4) = ry;
  v(5) = rz;
  return v;
}

ToolPath parse_path_csv(const std::string& text, const std::string& file, const PathOptions& o) {
  check_options(o, file);
  const std::vector<std::string> lines = split_lines(text);
  size_t h = 0;
  while (h < lines.size() && blank_or_comment(lines[h])) ++h;
  if (h == lines.size()) throw ParseError(file, 0, 0, "empty path file (no header line)");
  const int header_line = static_cast<int>(h) + 1;
  const std::vector<Field> head = split_csv(lines[h]);
  std::vector<Column> cols;
  std::map<std::string, int> seen;
  int count[8] = {0};
  for (const Field& f : head) {
    if (f.text.empty()) throw ParseError(file, header_line, f.col, "empty column name");
    if (seen.count(f.text))
      throw ParseError(file, header_line, f.col, "duplicate column '" + f.text + "'");
    seen[f.text] = 1;
    const Column c = classify(f.text, file, header_line, f.col);
    cols.push_back(c);
    ++count[static_cast<int>(c.kind)];
  }
  auto need_all = [&](Kind k, int n, const char* what, bool required) {
    const int got = count[static_cast<int>(k)];
    if (got == 0 && !required) return false;
    if (got != n)
      throw ParseError(file, header_line, 1,
                       std::string("the header needs all of ") + what + " (with units), has " +
                           std::to_string(got) + " of them");
    return true;
  };
  need_all(Kind::x, 3, "x, y, z", true);
  const bool has_rpy = need_all(Kind::rpy, 3, "rx, ry, rz", false);
  const bool has_quat = need_all(Kind::quat, 4, "qw, qx, qy, qz", false);
  if (has_rpy && has_quat)
    throw ParseError(file, header_line, 1,
                     "give the orientation either as rx, ry, rz or as qw, qx, qy, qz, not both");
  const bool has_force = need_all(Kind::force, 3, "fx, fy, fz", false);
  const bool has_moment = need_all(Kind::moment, 3, "mx, my, mz", false);
  if (has_moment && !has_force)
    throw ParseError(file, header_line, 1, "moment columns need the force columns fx, fy, fz");
  ToolPath path;
  path.source = file;
  path.has_wrench = has_force;
  const Eigen::Matrix3d rf = o.frame.block<3, 3>(0, 0);
  for (size_t li = h + 1; li < lines.size(); ++li) {
    if (blank_or_comment(lines[li])) continue;
    const int line_no = static_cast<int>(li) + 1;
    const std::vector<Field> fields = split_csv(lines[li]);
    if (fields.size() != cols.size())
      throw ParseError(file, line_no, 1,
                       "row has " + std::to_string(fields.size()) + " fields, the header has " +
                           std::to_string(cols.size()));
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), rpy = Eigen::Vector3d::Zero(),
                    f = Eigen::Vector3d::Zero(), m = Eigen::Vector3d::Zero();
    Eigen::Vector4d q = Eigen::Vector4d::Zero();
    PathPoint pt;
    pt.line = line_no;
    for (size_t c = 0; c < cols.size(); ++c) {
      const Column& col = cols[c];
      if (col.kind == Kind::ignored || col.kind == Kind::id) continue;
      double v;
      if (!parse_double(fields[c].text, &v))
        throw ParseError(
            file, line_no, fields[c].col,
            "'" + fields[c].text + "' is not a finite number (column '" + head[c].text + "')");
      v *= col.scale;
      switch (col.kind) {
        case Kind::x:
          p(col.index) = v;
          break;
        case Kind::rpy:
          rpy(col.index) = v;
          break;
        case Kind::quat:
          q(col.index) = v;
          break;
        case Kind::force:
          f(col.index) = v;
          break;
        case Kind::moment:
          m(col.index) = v;
          break;
        case Kind::feed:
          pt.feed_m_s = v;
          break;
        default:
          break;
      }
    }
    Eigen::Matrix3d r = o.tool_orientation;
    if (has_rpy) {
      Eigen::Matrix<double, 6, 1> v;
      v << 0, 0, 0, rpy;
      r = pose_from_xyz_rpy(v).block<3, 3>(0, 0);
    } else if (has_quat) {
      const double n = q.norm();
      if (std::abs(n - 1.0) > 1e-3)
        throw ParseError(file, line_no, 1,
                         "quaternion (qw, qx, qy, qz) has norm " + std::to_string(n) + ", not 1");
      r = Eigen::Quaterniond(q(0) / n, q(1) / n, q(2) / n, q(3) / n).toRotationMatrix();
    }
    pt.pose = frame_pose(o, p, r);
    pt.wrench.head<3>() = rf * f;
    pt.wrench.tail<3>() = rf * m;
    path.points.push_back(pt);
  }
  if (path.points.empty()) throw ParseError(file, header_line, 0, "the path has no points");
  return path;
}

ToolPath parse_gcode(const std::string& text, const std::string& file, const PathOptions& o) {
  check_options(o, file);
  const std::vector<std::string> lines = split_lines(text);
  ToolPath path;
  path.source = file;
  double unit = 1e-3;  // G21
  bool absolute = true;
  int motion = -1;                                // 0, 1, 2 (G2, clockwise) or 3 (G3) once set
  int plane = 17;                                 // G17 XY, G18 ZX, G19 YZ: the plane of arcs
  double feed = 0.0;                              // [m/s]
  Eigen::Vector3d pos = Eigen::Vector3d::Zero();  // workpiece frame [m]
  // Axes whose position is known: a program starts wherever the machine stands, so no point is
  // made before X, Y and Z have all been given (typically "G0 X.. Y.." then "G43 Z.. H..").
  bool known[3] = {false, false, false};
  for (size_t li = 0; li < lines.size(); ++li) {
    const int line_no = static_cast<int>(li) + 1;
    const std::string& s = lines[li];
    // Words of the line, comments removed.
    struct Word {
      char letter;
      double value;
      int col;
      std::string text;
    };
    std::vector<Word> words;
    size_t i = 0;
    while (i < s.size()) {
      const char ch = s[i];
      if (ch == ' ' || ch == '\t') {
        ++i;
        continue;
      }
      if (ch == ';') break;
      if (ch == '(') {
        const size_t close = s.find(')', i);
        if (close == std::string::npos)
          throw ParseError(file, line_no, static_cast<int>(i) + 1, "unterminated comment '('");
        i = close + 1;
        continue;
      }
      if (ch == '%' && words.empty()) {
        i = s.size();
        break;
      }
      if (ch == '/' && words.empty()) {  // block delete: the line runs unless skipped
        ++i;
        continue;
      }
      if (!std::isalpha(static_cast<unsigned char>(ch)))
        throw ParseError(
            file, line_no, static_cast<int>(i) + 1,
            std::string("unexpected character '") + ch + "' (expected a word such as G1 or X10)");
      const int col = static_cast<int>(i) + 1;
      const char letter = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
      ++i;
      size_t j = i;
      while (j < s.size() && (s[j] == ' ' || s[j] == '\t')) ++j;
      size_t k = j;
      while (k < s.size() && (std::isdigit(static_cast<unsigned char>(s[k])) || s[k] == '.' ||
                              s[k] == '-' || s[k] == '+'))
        ++k;
      const std::string num = s.substr(j, k - j);
      double v;
      if (!parse_double(num, &v))
        throw ParseError(file, line_no, col,
                         std::string("expected a number after '") + letter + "'" +
                             (num.empty() ? "" : ", got '" + num + "'"));
      words.push_back({letter, v, col, letter + num});
      i = k;
    }
    if (words.empty()) continue;
    bool has_xyz = false, non_path_move = false, has_ijk = false, has_r = false;
    Eigen::Vector3d given = Eigen::Vector3d::Zero(), ijk = Eigen::Vector3d::Zero();
    double radius = 0.0;
    bool axis_given[3] = {false, false, false};
    // Modal G codes first (units and distance mode apply to the coordinates of the line).
    for (const Word& w : words) {
      if (w.letter != 'G') continue;
      const double g = w.value;
      if (g == 0 || g == 1 || g == 2 || g == 3)
        motion = static_cast<int>(g);
      else if (g == 17 || g == 18 || g == 19)
        plane = static_cast<int>(g);
      else if (g == 20)
        unit = 25.4e-3;
      else if (g == 21)
        unit = 1e-3;
      else if (g == 90)
        absolute = true;
      else if (g == 91)
        absolute = false;
      else if (g == 28 || g == 30 || g == 53)
        non_path_move = true;  // home / machine-coordinate move: not a point of the path
      else if (g == 4 || g == 40 || g == 43 || g == 49 || g == 80 || g == 94 || g == 61 ||
               g == 64 || (g >= 54 && g <= 59))
        continue;  // dwell, cutter and tool length compensation (the robot's tool is its
                   // measured point), work offsets (frame from the caller), feed mode
      else
        throw ParseError(file, line_no, w.col,
                         "unsupported G-code " + w.text +
                             " (supported: G0-G4, G17-G21, G28, G30, G40, G43, G49, G53-G59, "
                             "G61, G64, G80, G90, G91, G94)");
    }
    for (const Word& w : words) {
      switch (w.letter) {
        case 'G':
        case 'M':
        case 'N':
        case 'O':
        case 'S':
        case 'T':
        case 'H':
        case 'D':
        case 'P':  // dwell time, G64 tolerance
          break;
        case 'F':
          if (!(w.value > 0))
            throw ParseError(file, line_no, w.col, "feed " + w.text + " must be > 0");
          feed = w.value * unit / 60.0;
          break;
        case 'X':
        case 'Y':
        case 'Z': {
          const int a = w.letter - 'X';
          if (axis_given[a])
            throw ParseError(file, line_no, w.col,
                             std::string("axis ") + w.letter + " given twice");
          axis_given[a] = true;
          given(a) = w.value * unit;
          has_xyz = true;
          break;
        }
        case 'A':
        case 'B':
        case 'C':
          // A 3+2 post writes the rotary axes at zero in its safe-start lines: no rotation.
          if (w.value != 0)
            throw ParseError(
                file, line_no, w.col,
                std::string("rotary axis word '") + w.text +
                    "': 4- and 5-axis programs are not supported, the tool orientation is "
                    "fixed; give it instead with the tool orientation option (stiff "
                    "compensate --tool-rpy rx,ry,rz), or write the path as CSV with rx/ry/rz "
                    "or quaternion columns");
          break;
        case 'I':
        case 'J':
        case 'K':
          ijk(w.letter - 'I') = w.value * unit;  // arc centre, relative to the start (G91.1)
          has_ijk = true;
          break;
        case 'R':
          radius = w.value * unit;
          has_r = true;
          break;
        default:
          throw ParseError(file, line_no, w.col, std::string("unsupported word '") + w.text + "'");
      }
    }
    if (non_path_move) {
      // The machine goes home (or to machine coordinates): where the tool then stands in the
      // workpiece frame is not known from the program.
      for (bool& k : known) k = false;
      continue;
    }
    if (!has_xyz && !(has_ijk && (motion == 2 || motion == 3))) continue;
    if (motion < 0)
      throw ParseError(file, line_no, words.front().col,
                       "coordinates before any G0/G1 motion command");
    if (!absolute && !(known[0] && known[1] && known[2]))
      throw ParseError(file, line_no, words.front().col,
                       "incremental move (G91) before the position is known (X, Y and Z not all "
                       "given in G90)");
    Eigen::Vector3d end = pos;
    for (int a = 0; a < 3; ++a)
      if (axis_given[a]) end(a) = absolute ? given(a) : pos(a) + given(a);
    if (motion >= 1 && feed <= 0)
      throw ParseError(file, line_no, words.front().col,
                       std::string(motion == 1 ? "G1" : "arc") + " move without a feed (F word)");
    const bool start_known = known[0] && known[1] && known[2];
    for (int a = 0; a < 3; ++a) known[a] = known[a] || axis_given[a];
    if (!(known[0] && known[1] && known[2])) {
      if (motion >= 2)
        throw ParseError(file, line_no, words.front().col,
                         "arc before the position is known (X, Y and Z not all given)");
      pos = end;  // not yet a point: the machine's start is unknown
      continue;
    }
    if ((motion == 2 || motion == 3) && !start_known)
      throw ParseError(file, line_no, words.front().col,
                       "arc before the position is known (X, Y and Z not all given)");
    std::vector<Eigen::Vector3d> targets;  // end points of the pieces of this move
    if (motion == 2 || motion == 3) {
      // Arc in the selected plane (u, v) with the third axis w moving linearly (helix).
      const int u = plane == 17 ? 0 : plane == 18 ? 2 : 1;
      const int v = plane == 17 ? 1 : plane == 18 ? 0 : 2;
      const int wax = 3 - u - v;
      const char* plane_name = plane == 17 ? "G17 (XY)" : plane == 18 ? "G18 (ZX)" : "G19 (YZ)";
      if (has_ijk == has_r)
        throw ParseError(file, line_no, words.front().col,
                         std::string("arc needs either the centre (I, J, K) or the radius R, ") +
                             (has_r ? "not both" : "got neither"));
      if (has_ijk && ijk(wax) != 0)
        throw ParseError(file, line_no, words.front().col,
                         std::string("arc centre offset along the axis normal to the plane ") +
                             plane_name + " must be 0");
      const Eigen::Vector2d a(pos(u), pos(v)), b(end(u), end(v));
      Eigen::Vector2d c;
      // G2 is clockwise seen from the positive normal axis; in G18 the normal is +Y with the
      // plane ordered (Z, X), which keeps the same right-handed rule with (u, v) = (Z, X).
      const double sense = motion == 3 ? 1.0 : -1.0;
      if (has_ijk) {
        c = a + Eigen::Vector2d(ijk(u), ijk(v));
      } else {
        const double chord = (b - a).norm();
        const double r = std::abs(radius);
        if (chord == 0 || !(r > 0))
          throw ParseError(file, line_no, words.front().col,
                           "R arc needs a radius > 0 and an end point other than the start");
        if (chord > 2 * r * (1 + 1e-9))
          throw ParseError(file, line_no, words.front().col,
                           "R arc: the end point is farther from the start than the diameter");
        const double h = std::sqrt(std::max(0.0, r * r - chord * chord / 4));
        const Eigen::Vector2d mid = (a + b) / 2, d = (b - a) / chord;
        const Eigen::Vector2d left(-d(1), d(0));
        // R > 0: the short arc (<= 180 deg); R < 0: the long one.
        const double side = (radius > 0 ? 1.0 : -1.0) * sense;
        c = mid + side * h * left;
      }
      const double r0 = (a - c).norm(), r1 = (b - c).norm();
      if (!(r0 > 0)) throw ParseError(file, line_no, words.front().col, "arc with zero radius");
      // Same tolerance as common CNC controllers: 0.002 mm or 0.1 % of the radius.
      if (std::abs(r1 - r0) > std::max(2e-6, 1e-3 * r0))
        throw ParseError(file, line_no, words.front().col,
                         "arc end point is not on the circle: radius " + std::to_string(r0 * 1e3) +
                             " mm at the start, " + std::to_string(r1 * 1e3) +
                             " mm at the end (plane " + plane_name + ")");
      const double t0 = std::atan2(a(1) - c(1), a(0) - c(0));
      double t1 = std::atan2(b(1) - c(1), b(0) - c(0));
      double sweep = t1 - t0;
      if (sense > 0) {
        while (sweep <= 1e-12) sweep += 2 * kPiPath;
      } else {
        while (sweep >= -1e-12) sweep -= 2 * kPiPath;
      }
      // Pieces: at most segment_m long, and chords within kArcChordTolerance of the circle.
      const double length = std::hypot(std::abs(sweep) * r0, end(wax) - pos(wax));
      const double max_angle = 2 * std::acos(std::max(-1.0, 1 - kArcChordTolerance / r0));
      double want = std::ceil(std::abs(sweep) / max_angle - 1e-9);
      if (o.segment_m > 0) want = std::max(want, std::ceil(length / o.segment_m - 1e-9));
      if (!(want <= 1e6))
        throw ParseError(file, line_no, words.front().col,
                         "this arc splits into more than 1000000 segments: check the units or "
                         "the segment length");
      const int pieces = std::max(1, static_cast<int>(want));
      for (int k = 1; k <= pieces; ++k) {
        const double f = static_cast<double>(k) / pieces;
        Eigen::Vector3d p;
        if (k == pieces) {
          p = end;
        } else {
          p(u) = c(0) + r0 * std::cos(t0 + f * sweep);
          p(v) = c(1) + r0 * std::sin(t0 + f * sweep);
          p(wax) = pos(wax) + f * (end(wax) - pos(wax));
        }
        targets.push_back(p);
      }
    } else {
      int pieces = 1;
      if (motion == 1 && o.segment_m > 0 && start_known) {
        // Checked before the conversion to int: a huge move (or coordinate) would overflow it.
        const double want = std::ceil((end - pos).norm() / o.segment_m - 1e-9);
        if (!(want <= 1e6))
          throw ParseError(file, line_no, words.front().col,
                           "this move splits into more than 1000000 segments of " +
                               std::to_string(o.segment_m) +
                               " m: check the units or the segment length");
        pieces = std::max(1, static_cast<int>(want));
      }
      for (int k = 1; k < pieces; ++k)
        targets.push_back(pos + (end - pos) * (static_cast<double>(k) / pieces));
      targets.push_back(end);  // exactly the programmed point
    }
    for (const Eigen::Vector3d& p : targets) {
      PathPoint pt;
      pt.pose = frame_pose(o, p, o.tool_orientation);
      pt.line = line_no;
      pt.feed_m_s = motion >= 1 ? feed : 0.0;
      pt.rapid = motion == 0;
      path.points.push_back(pt);
    }
    pos = end;
  }
  if (path.points.empty())
    throw ParseError(file, static_cast<int>(lines.size()), 0,
                     "the G-code has no move that reaches a known position (X, Y and Z all "
                     "given)");
  return path;
}

ToolPath read_path(const std::string& path, const PathOptions& options) {
  check_options(options, path);  // a bad option is refused whatever the file holds
  const std::string text = read_text_file(path);
  const size_t dot = path.find_last_of('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == "csv") return parse_path_csv(text, path, options);
  return parse_gcode(text, path, options);
}

}  // namespace stiff
