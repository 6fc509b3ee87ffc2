#include "stiff/io/dataset.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <set>
#include <sstream>

#include "io/number_text.hpp"
#include "stiff/error.hpp"
#include "stiff/io/text_io.hpp"
#include "stiff/kinematics/robot_model.hpp"

namespace stiff {
namespace {

constexpr double kPi = 3.141592653589793238462643383279502884;

// What a column holds; `index` is the component (0..2) or joint index.
enum class Kind {
  id,
  session,
  q,
  force,
  moment,
  displacement,
  rotation,
  sigma,
  time,
  position,
  euler,
  temperature,
  sigma_p,
  sigma_o,
  extra
};

struct Column {
  Kind kind = Kind::extra;
  int index = 0;
  double scale = 1.0;  // multiply to get SI
  std::string name;
};

struct Field {
  std::string text;
  int col;  // 1-based character column of the field start
};

// Split one CSV line (RFC 4180 quoting, no embedded newlines).
std::vector<Field> split_line(const std::string& line, const std::string& file, int line_no) {
  std::vector<Field> out;
  size_t i = 0;
  while (true) {
    Field f{std::string(), static_cast<int>(i) + 1};
    if (i < line.size() && line[i] == '"') {
      ++i;
      bool closed = false;
      while (i < line.size()) {
        if (line[i] == '"') {
          if (i + 1 < line.size() && line[i + 1] == '"') {
            f.text += '"';
            i += 2;
            continue;
          }
          closed = true;
          ++i;
          break;
        }
        f.text += line[i++];
      }
      if (!closed) throw ParseError(file, line_no, f.col, "unterminated quoted field");
      if (i < line.size() && line[i] != ',')
        throw ParseError(file, line_no, static_cast<int>(i) + 1, "text after a closing quote");
    } else {
      while (i < line.size() && line[i] != ',') f.text += line[i++];
      // Surrounding blanks are not part of a value.
      const auto b = f.text.find_first_not_of(" \t");
      const auto e = f.text.find_last_not_of(" \t");
      f.text = b == std::string::npos ? std::string() : f.text.substr(b, e - b + 1);
    }
    out.push_back(f);
    if (i >= line.size()) break;
    ++i;  // the comma
    if (i == line.size()) {
      out.push_back(Field{std::string(), static_cast<int>(i) + 1});
      break;
    }
  }
  return out;
}

bool lookup_unit(Kind kind, const std::string& unit, double* scale) {
  static const std::map<std::string, double> angle{{"rad", 1.0}, {"deg", kPi / 180.0}};
  static const std::map<std::string, double> force{{"N", 1.0}};
  static const std::map<std::string, double> moment{{"Nm", 1.0}, {"Nmm", 1e-3}};
  static const std::map<std::string, double> length{{"m", 1.0}, {"mm", 1e-3}, {"um", 1e-6}};
  static const std::map<std::string, double> rotation{{"rad", 1.0}, {"mrad", 1e-3}};
  static const std::map<std::string, double> time{{"s", 1.0}, {"min", 60.0}};
  static const std::map<std::string, double> celsius{{"C", 1.0}};
  static const std::map<std::string, double> small_angle{
      {"rad", 1.0}, {"deg", kPi / 180.0}, {"urad", 1e-6}};
  const std::map<std::string, double>* table = nullptr;
  switch (kind) {
    case Kind::euler:
      table = &angle;
      break;
    case Kind::temperature:
      table = &celsius;
      break;
    case Kind::sigma_o:
      table = &small_angle;
      break;
    case Kind::position:
    case Kind::sigma_p:
      table = &length;
      break;
    case Kind::q:
      table = &angle;
      break;
    case Kind::force:
      table = &force;
      break;
    case Kind::moment:
      table = &moment;
      break;
    case Kind::displacement:
    case Kind::sigma:
      table = &length;
      break;
    case Kind::rotation:
      table = &rotation;
      break;
    case Kind::time:
      table = &time;
      break;
    default:
      return false;
  }
  const auto it = table->find(unit);
  if (it == table->end()) return false;
  *scale = it->second;
  return true;
}

std::string accepted_units(Kind kind) {
  switch (kind) {
    case Kind::q:
    case Kind::euler:
      return "_rad, _deg";
    case Kind::temperature:
      return "_C";
    case Kind::sigma_o:
      return "_rad, _deg, _urad";
    case Kind::position:
    case Kind::sigma_p:
      return "_m, _mm, _um";
    case Kind::force:
      return "_N";
    case Kind::moment:
      return "_Nm, _Nmm";
    case Kind::displacement:
    case Kind::sigma:
      return "_m, _mm, _um";
    case Kind::rotation:
      return "_rad, _mrad";
    case Kind::time:
      return "_s, _min";
    default:
      return "";
  }
}

// Classify a header name; throws on a known quantity with a missing or unknown unit.
Column classify(const std::string& name, const std::string& file, int line, int col) {
  Column c;
  c.name = name;
  if (name == "id") {
    c.kind = Kind::id;
    return c;
  }
  if (name == "session") {
    c.kind = Kind::session;
    return c;
  }
  struct Base {
    std::string base;
    Kind kind;
    int index;
  };
  std::vector<Base> bases = {
      {"fx", Kind::force, 0},        {"fy", Kind::force, 1},        {"fz", Kind::force, 2},
      {"mx", Kind::moment, 0},       {"my", Kind::moment, 1},       {"mz", Kind::moment, 2},
      {"dx", Kind::displacement, 0}, {"dy", Kind::displacement, 1}, {"dz", Kind::displacement, 2},
      {"rx", Kind::rotation, 0},     {"ry", Kind::rotation, 1},     {"rz", Kind::rotation, 2},
      {"sigma_d", Kind::sigma, 0},   {"t", Kind::time, 0},          {"px", Kind::position, 0},
      {"py", Kind::position, 1},     {"pz", Kind::position, 2},     {"a", Kind::euler, 0},
      {"b", Kind::euler, 1},         {"c", Kind::euler, 2},         {"temp", Kind::temperature, 0},
      {"sigma_p", Kind::sigma_p, 0}, {"sigma_o", Kind::sigma_o, 0}};
  // q<k>: joint columns.
  if (name.size() >= 2 && name[0] == 'q' && std::isdigit(static_cast<unsigned char>(name[1]))) {
    size_t k = 1;
    while (k < name.size() && std::isdigit(static_cast<unsigned char>(name[k]))) ++k;
    // At most 4 digits are read: more is beyond any robot (and would overflow atoi).
    const int joint = k - 1 > 4 ? kMaxJoints + 1 : std::atoi(name.substr(1, k - 1).c_str());
    if (joint > kMaxJoints)
      throw ParseError(file, line, col,
                       "column '" + name + "': joint " + name.substr(1, k - 1) +
                           ", but a robot has at most " + std::to_string(kMaxJoints) + " joints");
    if (joint >= 1) bases.push_back({name.substr(0, k), Kind::q, joint - 1});
  }
  for (const auto& b : bases) {
    if (name == b.base)
      throw ParseError(
          file, line, col,
          "column '" + name + "' has no unit suffix (use " + accepted_units(b.kind) + ")");
    if (name.compare(0, b.base.size() + 1, b.base + "_") != 0) continue;
    const std::string unit = name.substr(b.base.size() + 1);
    if (unit.find('_') != std::string::npos) continue;  // e.g. fx_flange_N: an extra column
    c.kind = b.kind;
    c.index = b.index;
    if (!lookup_unit(b.kind, unit, &c.scale))
      throw ParseError(file, line, col,
                       "column '" + name + "': unknown unit '" + unit +
                           "' (accepted: " + accepted_units(b.kind) + ")");
    return c;
  }
  c.kind = Kind::extra;
  return c;
}

double parse_number(const Field& f, const Column& c, const std::string& file, int line) {
  if (f.text.empty()) throw ParseError(file, line, f.col, "column '" + c.name + "': empty value");
  char* end = nullptr;
  const double v = std::strtod(f.text.c_str(), &end);
  if (end != f.text.c_str() + f.text.size())
    throw ParseError(file, line, f.col,
                     "column '" + c.name + "': '" + f.text + "' is not a number");
  if (!std::isfinite(v))
    throw ParseError(file, line, f.col,
                     "column '" + c.name + "': '" + f.text + "' is not a finite number");
  return v * c.scale;
}

std::string quote_if_needed(const std::string& s) {
  // Unquoted fields are trimmed on reading: quote anything whose blanks must survive.
  const bool blank_edge =
      !s.empty() && (s.front() == ' ' || s.front() == '\t' || s.back() == ' ' || s.back() == '\t');
  if (!blank_edge && s.find_first_of(",\"\n\r#") == std::string::npos) return s;
  std::string o = "\"";
  for (char ch : s) o += ch == '"' ? std::string("\"\"") : std::string(1, ch);
  return o + "\"";
}

using detail::exact;

}  // namespace

std::string Dataset::meta(const std::string& key, const std::string& fallback) const {
  for (const auto& kv : metadata)
    if (kv.first == key) return kv.second;
  return fallback;
}

void Dataset::set_meta(const std::string& key, const std::string& value) {
  for (auto& kv : metadata)
    if (kv.first == key) {
      kv.second = value;
      return;
    }
  metadata.emplace_back(key, value);
}

int Dataset::extra_index(const std::string& name) const {
  for (size_t i = 0; i < extra_columns.size(); ++i)
    if (extra_columns[i] == name) return static_cast<int>(i);
  return -1;
}

Dataset parse_measurements_csv(const std::string& text_in, const std::string& file, int dof) {
  std::string text = text_in;
  if (text.compare(0, 3, "\xEF\xBB\xBF") == 0) text.erase(0, 3);  // UTF-8 byte-order mark
  // Lines that end in CR alone (classic Mac) read as one long line: say so, not "unknown unit".
  for (size_t i = text.find('\r'); i != std::string::npos; i = text.find('\r', i + 1))
    if (i + 1 < text.size() && text[i + 1] != '\n')
      throw ParseError(file, 1, 1,
                       "lines end in a carriage return alone (CR); save the file with LF or "
                       "CRLF line ends");
  Dataset data;
  std::vector<Column> columns;
  std::map<std::string, std::string> ids;  // id -> its session
  std::vector<int> row_lines;
  bool have_header = false;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  int header_line = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find('\0') != std::string::npos)
      throw ParseError(file, line_no, 1, "binary data (NUL byte) in a text file");
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos) continue;
    if (line[first] == '#') {
      const std::string body = line.substr(first + 1);
      const auto colon = body.find(':');
      if (colon != std::string::npos) {
        auto trim = [](std::string s) {
          const auto b = s.find_first_not_of(" \t");
          const auto e = s.find_last_not_of(" \t");
          return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
        };
        const std::string key = trim(body.substr(0, colon));
        if (!key.empty() && key.find(' ') == std::string::npos)
          data.set_meta(key, trim(body.substr(colon + 1)));
      }
      continue;
    }
    const auto fields = split_line(line, file, line_no);
    if (!have_header) {
      have_header = true;
      header_line = line_no;
      std::set<std::string> seen;
      std::map<std::pair<int, int>, std::string> quantity_column;
      int max_q = 0;
      std::set<int> qs;
      for (const auto& f : fields) {
        if (f.text.empty()) throw ParseError(file, line_no, f.col, "empty column name");
        if (!seen.insert(f.text).second)
          throw ParseError(file, line_no, f.col, "duplicate column '" + f.text + "'");
        Column c = classify(f.text, file, line_no, f.col);
        if (c.kind != Kind::q && c.kind != Kind::extra && c.kind != Kind::id &&
            c.kind != Kind::session) {
          // dx_mm beside dx_m: the same quantity in two units; which is meant is a guess.
          const auto [it, fresh] =
              quantity_column.emplace(std::make_pair(static_cast<int>(c.kind), c.index), f.text);
          if (!fresh)
            throw ParseError(file, line_no, f.col,
                             "columns '" + it->second + "' and '" + f.text +
                                 "' give the same quantity twice; keep one");
        }
        if (c.kind == Kind::q) {
          if (!qs.insert(c.index).second)
            throw ParseError(file, line_no, f.col,
                             "joint q" + std::to_string(c.index + 1) + " given twice");
          max_q = std::max(max_q, c.index + 1);
          if (dof > 0 && c.index >= dof)
            throw ParseError(file, line_no, f.col,
                             "column '" + f.text + "': the robot has " + std::to_string(dof) +
                                 " joints (joint count mismatch)");
        }
        if (c.kind == Kind::extra) {
          c.index = static_cast<int>(data.extra_columns.size());
          data.extra_columns.push_back(f.text);
        }
        columns.push_back(c);
      }
      // What a header that names no joint usually is: another separator or another case.
      std::string hint;
      if (fields.size() == 1 && line.find_first_of(";\t") != std::string::npos)
        hint = " (the header has one column: columns are separated by commas, this file uses " +
               std::string(line.find(';') != std::string::npos ? "semicolons" : "tabs") + ")";
      else
        for (const auto& f : fields)
          if (hint.empty() && f.text.size() > 1 && f.text[0] == 'Q' &&
              std::isdigit(static_cast<unsigned char>(f.text[1])))
            hint = " (column names are lower case: '" + f.text + "' must be written '" + [&] {
              std::string l = f.text;
              for (char& ch : l)
                ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
              return l;
            }() + "')";
      const int n = dof > 0 ? dof : max_q;
      if (n == 0)
        throw ParseError(file, line_no, 1, "missing joint columns q1.. (e.g. q1_deg)" + hint);
      for (int j = 0; j < n; ++j)
        if (!qs.count(j))
          throw ParseError(file, line_no, 1,
                           "missing required column q" + std::to_string(j + 1) +
                               (dof > 0 ? " (the robot has " + std::to_string(dof) + " joints)"
                                        : std::string()) +
                               hint);
      data.dof = n;
      std::set<std::pair<Kind, int>> have;
      for (const auto& c : columns) have.insert({c.kind, c.index});
      auto group = [&](Kind k, const char* names, bool required) {
        const int count = have.count({k, 0}) + have.count({k, 1}) + have.count({k, 2});
        if (count == 3) return true;
        if (count == 0 && !required) return false;
        throw ParseError(file, line_no, 1,
                         std::string("missing required column: ") + names + " must all be present");
      };
      data.has_position = group(Kind::position, "px, py, pz", false);
      data.has_orientation = group(Kind::euler, "a, b, c", false);
      if (data.has_orientation && !data.has_position)
        throw ParseError(file, line_no, 1,
                         "Euler angles a, b, c need the absolute position columns px, py, pz");
      // Absolute data may come without a load (the robot's own weight only).
      data.has_force = group(Kind::force, "fx, fy, fz", !data.has_position);
      data.has_moment = group(Kind::moment, "mx, my, mz", false);
      data.has_displacement = group(Kind::displacement, "dx, dy, dz", false);
      data.has_rotation = group(Kind::rotation, "rx, ry, rz", false);
      data.has_temperature = have.count({Kind::temperature, 0}) > 0;
      data.has_sigma_p = have.count({Kind::sigma_p, 0}) > 0;
      data.has_sigma_o = have.count({Kind::sigma_o, 0}) > 0;
      if (data.has_orientation) {
        const std::string conv = data.meta("euler");
        if (conv == "xyz")
          data.euler = EulerConvention::xyz;
        else if (conv == "zyx")
          data.euler = EulerConvention::zyx;
        else
          throw ParseError(
              file, line_no, 1,
              conv.empty()
                  ? std::string("Euler angles a, b, c without their convention: add a metadata "
                                "line '# euler: xyz' (R = Rx(a) Ry(b) Rz(c)) or '# euler: zyx' "
                                "(R = Rz(a) Ry(b) Rx(c)) before the header")
                  : "unknown Euler convention '# euler: " + conv + "' (use xyz or zyx)");
      }
      data.has_sigma = have.count({Kind::sigma, 0}) > 0;
      data.has_time = have.count({Kind::time, 0}) > 0;
      data.has_session = have.count({Kind::session, 0}) > 0;
      data.has_id = have.count({Kind::id, 0}) > 0;
      continue;
    }
    if (fields.size() != columns.size())
      throw ParseError(file, line_no, fields.back().col,
                       "wrong field count: " + std::to_string(fields.size()) +
                           " fields, the header (line " + std::to_string(header_line) + ") has " +
                           std::to_string(columns.size()));
    Measurement m;
    m.q = Eigen::VectorXd::Zero(data.dof);
    m.extra.resize(data.extra_columns.size());
    // Which kind of row it is: a mixed file leaves the other kind's group empty.
    int filled_p = 0, filled_d = 0, filled_e = 0;
    for (size_t k = 0; k < fields.size(); ++k) {
      if (fields[k].text.empty()) continue;
      filled_p += columns[k].kind == Kind::position;
      filled_d += columns[k].kind == Kind::displacement;
      filled_e += columns[k].kind == Kind::euler;
    }
    const bool mixed = data.has_position && data.has_displacement;
    m.absolute = data.has_position && (!data.has_displacement || filled_p > 0);
    if (mixed && filled_p > 0 && filled_d > 0)
      throw ParseError(file, line_no, 1,
                       "row has both an absolute position (px, py, pz) and a displacement (dx, "
                       "dy, dz); give one of them");
    if (mixed && filled_p == 0 && filled_d == 0)
      throw ParseError(file, line_no, 1,
                       "row has neither an absolute position (px, py, pz) nor a displacement "
                       "(dx, dy, dz)");
    m.has_orientation = m.absolute && filled_e > 0;
    Eigen::Vector3d euler = Eigen::Vector3d::Zero();
    double temperature = std::nan("");
    for (size_t k = 0; k < fields.size(); ++k) {
      const Column& c = columns[k];
      const Field& f = fields[k];
      // Cells that may stay empty: the other kind's group, a load or orientation that an
      // absolute row does not have, per-row temperature and standard deviations.
      if (f.text.empty()) {
        const bool other = (m.absolute && (c.kind == Kind::displacement ||
                                           c.kind == Kind::rotation || c.kind == Kind::sigma)) ||
                           (!m.absolute && (c.kind == Kind::position || c.kind == Kind::euler ||
                                            c.kind == Kind::sigma_p || c.kind == Kind::sigma_o ||
                                            c.kind == Kind::temperature));
        const bool optional = (m.absolute && (c.kind == Kind::force || c.kind == Kind::moment ||
                                              c.kind == Kind::sigma_p || c.kind == Kind::sigma_o ||
                                              (c.kind == Kind::euler && !m.has_orientation)));
        if (other || optional) continue;
      }
      switch (c.kind) {
        case Kind::position:
          m.position(c.index) = parse_number(f, c, file, line_no);
          break;
        case Kind::euler:
          euler(c.index) = parse_number(f, c, file, line_no);
          // Degrees read as radians: no Euler angle needs more than one turn.
          if (std::abs(euler(c.index)) > 2.0 * kPi + 1e-9)
            throw ParseError(file, line_no, f.col,
                             "column '" + c.name + "': " + f.text +
                                 " is more than a full turn; are these degrees in a _rad "
                                 "column?");
          break;
        case Kind::temperature:
          temperature = parse_number(f, c, file, line_no);
          if (temperature < -273.15)
            throw ParseError(file, line_no, f.col, "column '" + c.name + "': below absolute zero");
          break;
        case Kind::sigma_p:
          m.sigma_p = parse_number(f, c, file, line_no);
          if (m.sigma_p <= 0)
            throw ParseError(file, line_no, f.col, "column '" + c.name + "': must be > 0");
          break;
        case Kind::sigma_o:
          m.sigma_o = parse_number(f, c, file, line_no);
          if (m.sigma_o <= 0)
            throw ParseError(file, line_no, f.col, "column '" + c.name + "': must be > 0");
          break;
        case Kind::id:
          if (f.text.empty()) throw ParseError(file, line_no, f.col, "empty id");
          m.id = f.text;
          break;
        case Kind::session:
          m.session = f.text;
          break;
        case Kind::q:
          m.q(c.index) = parse_number(f, c, file, line_no);
          break;
        case Kind::force:
          m.force(c.index) = parse_number(f, c, file, line_no);
          break;
        case Kind::moment:
          m.moment(c.index) = parse_number(f, c, file, line_no);
          break;
        case Kind::displacement:
          m.displacement(c.index) = parse_number(f, c, file, line_no);
          break;
        case Kind::rotation:
          m.rotation(c.index) = parse_number(f, c, file, line_no);
          break;
        case Kind::sigma:
          m.sigma_d = parse_number(f, c, file, line_no);
          if (m.sigma_d <= 0)
            throw ParseError(file, line_no, f.col, "column '" + c.name + "': must be > 0");
          break;
        case Kind::time:
          m.time = parse_number(f, c, file, line_no);
          break;
        case Kind::extra:
          m.extra[c.index] = f.text;
          break;
      }
    }
    if (data.has_id) {
      const auto found = ids.find(m.id);
      if (found != ids.end())
        throw ParseError(
            file, line_no, 1,
            "duplicate id '" + m.id + "'" +
                (found->second != m.session ? " (already in session '" + found->second +
                                                  "'; ids must be unique across sessions)"
                                            : std::string()));
      ids.emplace(m.id, m.session);
    }
    if (m.has_orientation && filled_e != 3)
      throw ParseError(file, line_no, 1, "Euler angles a, b, c must be given together");
    if (m.absolute) {
      if (m.session.empty())
        throw ParseError(file, line_no, 1,
                         "absolute row without a session: every absolute row needs a "
                         "'session' (one placement of the instrument, registered on its own)");
      if (m.has_orientation)
        m.orientation = euler_to_matrix(data.euler, euler(0), euler(1), euler(2));
      if (data.has_temperature) {
        if (std::isnan(temperature))
          throw ParseError(file, line_no, 1, "column 'temp': empty value on an absolute row");
        m.temperature = temperature;
      }
    }
    if (!data.has_id) m.id = std::to_string(data.rows.size() + 1);
    row_lines.push_back(line_no);
    data.rows.push_back(std::move(m));
  }
  if (!have_header) throw ParseError(file, line_no > 0 ? line_no : 1, 1, "no header row");
  // Each session registers the instrument on its own: it needs enough absolute rows.
  std::map<std::string, int> per_session;
  std::map<std::string, int> first_line;
  for (size_t r = 0; r < data.rows.size(); ++r)
    if (data.rows[r].absolute) {
      ++per_session[data.rows[r].session];
      first_line.emplace(data.rows[r].session, row_lines[r]);
    }
  for (const auto& kv : per_session)
    if (kv.second < kMinRowsPerSession)
      throw ParseError(
          file, first_line[kv.first], 1,
          "session '" + kv.first + "' has " + std::to_string(kv.second) + " absolute row" +
              (kv.second == 1 ? "" : "s") + "; its registration needs at least " +
              std::to_string(kMinRowsPerSession) + " (non-collinear target positions)");
  return data;
}

Dataset read_measurements_csv(const std::string& path, int dof) {
  return parse_measurements_csv(read_text_file(path), path, dof);
}

std::string format_measurements_csv(const Dataset& data) {
  std::ostringstream o;
  Dataset meta = data;
  if (data.has_orientation)
    meta.set_meta("euler", data.euler == EulerConvention::xyz ? "xyz" : "zyx");
  for (const auto& kv : meta.metadata) o << "# " << kv.first << ": " << kv.second << "\n";
  const bool force = data.has_force || !data.has_position;
  std::vector<std::string> head;
  head.push_back("id");
  for (int j = 0; j < data.dof; ++j) head.push_back("q" + std::to_string(j + 1) + "_rad");
  if (force)
    for (const char* s : {"fx_N", "fy_N", "fz_N"}) head.push_back(s);
  if (data.has_moment)
    for (const char* s : {"mx_Nm", "my_Nm", "mz_Nm"}) head.push_back(s);
  if (data.has_displacement)
    for (const char* s : {"dx_m", "dy_m", "dz_m"}) head.push_back(s);
  if (data.has_rotation)
    for (const char* s : {"rx_rad", "ry_rad", "rz_rad"}) head.push_back(s);
  if (data.has_sigma) head.push_back("sigma_d_m");
  if (data.has_position)
    for (const char* s : {"px_m", "py_m", "pz_m"}) head.push_back(s);
  if (data.has_orientation)
    for (const char* s : {"a_rad", "b_rad", "c_rad"}) head.push_back(s);
  if (data.has_temperature) head.push_back("temp_C");
  if (data.has_sigma_p) head.push_back("sigma_p_m");
  if (data.has_sigma_o) head.push_back("sigma_o_rad");
  if (data.has_time) head.push_back("t_s");
  if (data.has_session) head.push_back("session");
  for (const auto& e : data.extra_columns) head.push_back(quote_if_needed(e));
  for (size_t k = 0; k < head.size(); ++k) o << (k ? "," : "") << head[k];
  o << "\n";
  // A cell of the other kind's group stays empty.
  auto cell = [&](bool present, double v) { o << "," << (present ? exact(v) : std::string()); };
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const auto& m = data.rows[r];
    const bool abs = m.absolute;
    o << quote_if_needed(m.id.empty() ? std::to_string(r + 1) : m.id);
    for (int j = 0; j < data.dof; ++j) o << "," << exact(j < m.q.size() ? m.q(j) : 0.0);
    if (force)
      for (int k = 0; k < 3; ++k) o << "," << exact(m.force(k));
    if (data.has_moment)
      for (int k = 0; k < 3; ++k) o << "," << exact(m.moment(k));
    if (data.has_displacement)
      for (int k = 0; k < 3; ++k) cell(!abs, m.displacement(k));
    if (data.has_rotation)
      for (int k = 0; k < 3; ++k) cell(!abs, m.rotation(k));
    if (data.has_sigma) cell(!abs || m.sigma_d > 0, m.sigma_d);
    if (data.has_position)
      for (int k = 0; k < 3; ++k) cell(abs, m.position(k));
    if (data.has_orientation) {
      const Eigen::Vector3d e = matrix_to_euler(data.euler, m.orientation);
      for (int k = 0; k < 3; ++k) cell(abs && m.has_orientation, e(k));
    }
    if (data.has_temperature) cell(abs, m.temperature);
    if (data.has_sigma_p) cell(abs && m.sigma_p > 0, m.sigma_p);
    if (data.has_sigma_o) cell(abs && m.sigma_o > 0, m.sigma_o);
    if (data.has_time) o << "," << exact(m.time);
    if (data.has_session) o << "," << quote_if_needed(m.session);
    for (size_t e = 0; e < data.extra_columns.size(); ++e)
      o << "," << quote_if_needed(e < m.extra.size() ? m.extra[e] : std::string());
    o << "\n";
  }
  return o.str();
}

void write_measurements_csv(const std::string& path, const Dataset& data) {
  write_text_file_atomic(path, format_measurements_csv(data));
}

void validate_dataset(const Dataset& data, int dof, bool need_displacement) {
  if (data.rows.empty()) throw InvalidArgument("dataset has no measurements");
  if (need_displacement && !data.has_displacement && !data.has_position)
    throw InvalidArgument(
        "dataset has no displacement columns dx, dy, dz nor absolute positions px, py, pz (is it "
        "a plan file?)");
  std::set<std::string> ids;
  for (size_t r = 0; r < data.rows.size(); ++r) {
    const auto& m = data.rows[r];
    const std::string where = "measurement " + std::to_string(r + 1) + " (id '" + m.id + "')";
    if (m.q.size() != dof)
      throw InvalidArgument(where + ": " + std::to_string(m.q.size()) + " joint values for a " +
                            std::to_string(dof) + "-joint robot");
    if (!m.orientation.allFinite())
      throw InvalidArgument(where + ": the orientation (a, b, c) is not finite");
    // A rotation: orthonormal and right-handed (a matrix set in code, not read from Euler
    // angles, may be neither).
    if (m.has_orientation &&
        ((m.orientation.transpose() * m.orientation - Eigen::Matrix3d::Identity()).norm() > 1e-6 ||
         m.orientation.determinant() < 0))
      throw InvalidArgument(where + ": the orientation is not a rotation matrix");
    if (!m.q.allFinite() || !m.force.allFinite() || !m.moment.allFinite() ||
        !m.displacement.allFinite() || !m.rotation.allFinite() || !std::isfinite(m.sigma_d) ||
        !std::isfinite(m.time) || !m.position.allFinite() || !std::isfinite(m.temperature) ||
        !std::isfinite(m.sigma_p) || !std::isfinite(m.sigma_o))
      throw InvalidArgument(where + ": a value is not finite");
    if (m.sigma_d < 0) throw InvalidArgument(where + ": sigma_d must be >= 0");
    if (m.sigma_p < 0 || m.sigma_o < 0)
      throw InvalidArgument(where + ": sigma_p and sigma_o must be >= 0");
    if (m.absolute && m.session.empty())
      throw InvalidArgument(where + ": an absolute row needs a session");
    if (!m.id.empty() && !ids.insert(m.id).second) throw InvalidArgument(where + ": duplicate id");
  }
}

int Dataset::absolute_rows() const {
  int n = 0;
  for (const auto& m : rows) n += m.absolute;
  return n;
}

Eigen::Matrix3d euler_to_matrix(EulerConvention c, double a, double b, double cc) {
  using Eigen::AngleAxisd;
  using Eigen::Vector3d;
  if (c == EulerConvention::xyz)
    return (AngleAxisd(a, Vector3d::UnitX()) * AngleAxisd(b, Vector3d::UnitY()) *
            AngleAxisd(cc, Vector3d::UnitZ()))
        .toRotationMatrix();
  return (AngleAxisd(a, Vector3d::UnitZ()) * AngleAxisd(b, Vector3d::UnitY()) *
          AngleAxisd(cc, Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Vector3d matrix_to_euler(EulerConvention c, const Eigen::Matrix3d& r) {
  // Closed forms of the two products (b in [-pi/2, pi/2]).
  if (c == EulerConvention::xyz) {
    // R = Rx(a) Ry(b) Rz(c): r02 = sin b, r12 = -sin a cos b, r22 = cos a cos b,
    // r01 = -cos b sin c, r00 = cos b cos c.
    const double b = std::asin(std::max(-1.0, std::min(1.0, r(0, 2))));
    return {std::atan2(-r(1, 2), r(2, 2)), b, std::atan2(-r(0, 1), r(0, 0))};
  }
  // R = Rz(a) Ry(b) Rx(c): r20 = -sin b, r10 = sin a cos b, r00 = cos a cos b,
  // r21 = cos b sin c, r22 = cos b cos c.
  const double b = std::asin(std::max(-1.0, std::min(1.0, -r(2, 0))));
  return {std::atan2(r(1, 0), r(0, 0)), b, std::atan2(r(2, 1), r(2, 2))};
}

}  // namespace stiff
