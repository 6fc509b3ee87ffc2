#include "stiff/io/robot_io.hpp"

#include <console_bridge/console.h>
#include <urdf_model/model.h>
#include <urdf_parser/urdf_parser.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <map>
#include <mutex>
#include <set>
#include <sstream>

#include "io/xml.hpp"
#include "stiff/error.hpp"
#include "stiff/io/text_io.hpp"
#include "yaml_load.hpp"

namespace stiff {
namespace {

using detail::xml_attribute;

constexpr double kPi = 3.141592653589793238462643383279502884;

struct YamlReader {
  std::string file;

  [[noreturn]] void fail(const YAML::Node& node, const std::string& reason) const {
    const auto m = node.Mark();
    throw ParseError(file, m.is_null() ? 0 : m.line + 1, m.is_null() ? 0 : m.column + 1, reason);
  }

  double number(const YAML::Node& node, const std::string& what) const {
    if (!node || !node.IsScalar()) fail(node, what + " must be a number");
    double v = 0.0;
    try {
      v = node.as<double>();
    } catch (const YAML::Exception&) {
      fail(node, what + " must be a number, got '" + node.Scalar() + "'");
    }
    if (!std::isfinite(v)) fail(node, what + " is not a finite number");
    return v;
  }

  Eigen::Vector3d vec3(const YAML::Node& node, const std::string& what, double scale) const {
    if (!node.IsSequence() || node.size() != 3) fail(node, what + " must be a list of 3 numbers");
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v(i) = number(node[i], what) * scale;
    return v;
  }

  void check_keys(const YAML::Node& map,
                  const std::set<std::string>& allowed,
                  const std::string& where) const {
    for (const auto& kv : map) {
      const auto key = kv.first.as<std::string>();
      if (!allowed.count(key)) fail(kv.first, "unknown key '" + key + "' in " + where);
    }
  }
};

double length_scale(const YamlReader& r, const YAML::Node& node) {
  const auto u = node.as<std::string>();
  if (u == "m") return 1.0;
  if (u == "mm") return 1e-3;
  r.fail(node, "unknown length unit '" + u + "' (use m or mm)");
}

double angle_scale(const YamlReader& r, const YAML::Node& node) {
  const auto u = node.as<std::string>();
  if (u == "rad") return 1.0;
  if (u == "deg") return kPi / 180.0;
  r.fail(node, "unknown angle unit '" + u + "' (use rad or deg)");
}

Eigen::Matrix4d matrix4(const YamlReader& r, const YAML::Node& node, const std::string& what) {
  if (!node.IsSequence() || node.size() != 16)
    r.fail(node, what + " must be a list of 16 numbers (row-major 4x4, m)");
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i) m(i / 4, i % 4) = r.number(node[i], what);
  return m;
}

}  // namespace

namespace {
RobotModel parse_robot_yaml_unguarded(const std::string& text, const std::string& file);
}  // namespace

RobotModel parse_robot_yaml(const std::string& text, const std::string& file) {
  // yaml-cpp throws on conversions the reader does not check itself (e.g. a key that is a
  // list); it must never escape as anything but a ParseError with its location.
  try {
    return parse_robot_yaml_unguarded(text, file);
  } catch (const YAML::Exception& e) {
    throw ParseError(file, e.mark.is_null() ? 0 : e.mark.line + 1,
                     e.mark.is_null() ? 0 : e.mark.column + 1, e.msg);
  }
}

namespace {
RobotModel parse_robot_yaml_unguarded(const std::string& text, const std::string& file) {
  YamlReader r{file};
  const YAML::Node root = detail::load_yaml_document(text, file);
  if (!root.IsMap()) throw ParseError(file, 1, 1, "a robot file must be a YAML mapping");
  r.check_keys(root,
               {"name", "convention", "units", "joints", "measured_point", "load_point", "tool",
                "gravity", "description"},
               "the robot file");

  RobotModel robot;
  robot.source_path = file;
  robot.name = root["name"] ? root["name"].as<std::string>() : std::string("robot");

  double ls = 1.0, as = 1.0;
  if (const auto units = root["units"]) {
    if (!units.IsMap()) r.fail(units, "units must be a mapping {length: mm|m, angle: deg|rad}");
    r.check_keys(units, {"length", "angle"}, "units");
    if (units["length"]) ls = length_scale(r, units["length"]);
    if (units["angle"]) as = angle_scale(r, units["angle"]);
  }

  if (!root["convention"]) throw ParseError(file, 1, 1, "missing key 'convention'");
  const auto conv_node = root["convention"];
  const auto conv = conv_node.as<std::string>();
  if (conv == "modified_dh")
    robot.convention = Convention::modified_dh;
  else if (conv == "standard_dh")
    robot.convention = Convention::standard_dh;
  else if (conv == "general" || conv == "urdf")
    robot.convention = Convention::urdf;
  else
    r.fail(conv_node,
           "unknown convention '" + conv + "' (use modified_dh, standard_dh or general)");

  const auto joints = root["joints"];
  if (!joints || !joints.IsSequence() || joints.size() == 0)
    throw ParseError(file, joints ? joints.Mark().line + 1 : 1, 1,
                     "'joints' must be a non-empty list");
  if (joints.size() > static_cast<size_t>(kMaxJoints))
    throw ParseError(file, joints.Mark().line + 1, 1,
                     "the robot has " + std::to_string(joints.size()) + " joints; at most " +
                         std::to_string(kMaxJoints) + " are supported");
  int index = 0;
  for (const auto& jn : joints) {
    ++index;
    const std::string where = "joint " + std::to_string(index);
    if (!jn.IsMap()) r.fail(jn, where + " must be a mapping");
    Joint j;
    if (robot.convention == Convention::urdf) {
      r.check_keys(jn, {"name", "pre", "axis", "post", "limits", "mass", "com"}, where);
      if (!jn["pre"] || !jn["axis"]) r.fail(jn, where + " needs 'pre' and 'axis'");
      j.pre = matrix4(r, jn["pre"], where + " pre");
      j.pre.block<3, 1>(0, 3) *= ls;
      j.axis = r.vec3(jn["axis"], where + " axis", 1.0);
      if (j.axis.norm() < 1e-9) r.fail(jn["axis"], where + " axis has zero length");
      j.axis.normalize();
      if (jn["post"]) {
        j.post = matrix4(r, jn["post"], where + " post");
        j.post.block<3, 1>(0, 3) *= ls;
      }
      for (double& v : j.dh) v = NAN;
    } else {
      r.check_keys(jn, {"name", "alpha", "a", "d", "theta_offset", "limits", "mass", "com"}, where);
      for (const char* key : {"alpha", "a", "d"})
        if (!jn[key]) r.fail(jn, where + " is missing '" + key + "'");
      const double alpha = r.number(jn["alpha"], where + " alpha") * as;
      const double a = r.number(jn["a"], where + " a") * ls;
      const double d = r.number(jn["d"], where + " d") * ls;
      const double off =
          jn["theta_offset"] ? r.number(jn["theta_offset"], where + " theta_offset") * as : 0.0;
      j = robot.convention == Convention::modified_dh ? modified_dh_joint(alpha, a, d, off)
                                                      : standard_dh_joint(alpha, a, d, off);
    }
    j.name = jn["name"] ? jn["name"].as<std::string>() : "joint" + std::to_string(index);
    if (const auto lim = jn["limits"]) {
      if (!lim.IsSequence() || lim.size() != 2)
        r.fail(lim, where + " limits must be [lower, upper]");
      j.lower = r.number(lim[0], where + " lower limit") * as;
      j.upper = r.number(lim[1], where + " upper limit") * as;
      if (!(j.lower < j.upper))
        r.fail(lim,
               where + " limits: lower must be less than upper (got an empty or negative range)");
    }
    if (jn["mass"]) {
      j.mass = r.number(jn["mass"], where + " mass");
      if (j.mass < 0) r.fail(jn["mass"], where + " mass must be >= 0 kg");
    }
    if (jn["com"]) j.com = r.vec3(jn["com"], where + " com", ls);
    robot.joints.push_back(j);
  }

  if (const auto mp = root["measured_point"])
    robot.measured_point = r.vec3(mp, "measured_point", ls);
  robot.load_point = robot.measured_point;
  if (const auto lp = root["load_point"]) robot.load_point = r.vec3(lp, "load_point", ls);
  if (const auto tool = root["tool"]) {
    if (!tool.IsMap()) r.fail(tool, "tool must be a mapping {mass: kg, com: [x, y, z]}");
    r.check_keys(tool, {"mass", "com"}, "tool");
    if (tool["mass"]) robot.tool_mass = r.number(tool["mass"], "tool mass");
    if (robot.tool_mass < 0) r.fail(tool["mass"], "tool mass must be >= 0 kg");
    if (tool["com"]) robot.tool_com = r.vec3(tool["com"], "tool com", ls);
  }
  if (const auto g = root["gravity"]) robot.gravity = r.vec3(g, "gravity", 1.0);
  return robot;
}

Eigen::Matrix4d urdf_pose(const urdf::Pose& p) {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  const Eigen::Quaterniond qr(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z);
  t.block<3, 3>(0, 0) = qr.normalized().toRotationMatrix();
  t.block<3, 1>(0, 3) = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  return t;
}

}  // namespace

namespace {

bool is_moving(const urdf::Joint& j) {
  if (j.type == urdf::Joint::CONTINUOUS) return true;
  if (j.type != urdf::Joint::REVOLUTE) return false;
  return !j.limits || j.limits->lower != j.limits->upper;  // lower = upper: locked
}

bool is_supported(const urdf::Joint& j) {
  return j.type == urdf::Joint::FIXED || j.type == urdf::Joint::REVOLUTE ||
         j.type == urdf::Joint::CONTINUOUS;
}

/// Links from `from` up to the root, `from` first.
std::vector<urdf::LinkConstSharedPtr> ancestry(urdf::LinkConstSharedPtr from) {
  std::vector<urdf::LinkConstSharedPtr> up;
  for (auto l = from; l; l = l->getParent()) up.push_back(l);
  return up;
}

std::string join_names(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

}  // namespace

RobotModel parse_robot_urdf(const std::string& text,
                            const std::string& file,
                            const std::string& tip_link,
                            const std::string& base_link,
                            RobotFileReport* report) {
  // urdfdom reports problems through console_bridge, which prints to stderr by default; the
  // library never prints (stiff.h): capture them for the error message instead.
  struct Capture : console_bridge::OutputHandler {
    std::string first_error;
    void log(const std::string& text, console_bridge::LogLevel level, const char*, int) override {
      if (level >= console_bridge::CONSOLE_BRIDGE_LOG_ERROR && first_error.empty())
        first_error = text;
    }
  } capture;
  check_xml_nesting(text, file);
  urdf::ModelInterfaceSharedPtr model;
  {
    static std::mutex handler_mutex;  // the output handler is process-wide
    std::lock_guard<std::mutex> lock(handler_mutex);
    console_bridge::OutputHandler* previous = console_bridge::getOutputHandler();
    console_bridge::useOutputHandler(&capture);
    try {
      model = urdf::parseURDF(text);
    } catch (...) {
      console_bridge::useOutputHandler(previous);
      throw;
    }
    console_bridge::useOutputHandler(previous);
  }
  if (!model)
    throw ParseError(
        file, 0, 0,
        "not a valid URDF document" +
            (capture.first_error.empty() ? std::string() : " (" + capture.first_error + ")"));
  auto root = model->getRoot();
  if (!root) throw ParseError(file, 0, 0, "URDF has no root link");
  // A link that is the child of two joints closes a kinematic loop (urdfdom keeps the last
  // parent and leaves the cycle in the child lists): walking it would never end.
  {
    std::map<std::string, std::string> parent_joint;
    for (const auto& [name, joint] : model->joints_) {
      if (!joint) continue;
      const auto [it, fresh] = parent_joint.emplace(joint->child_link_name, name);
      if (!fresh)
        throw ParseError(file, 0, 0,
                         "kinematic loop: link '" + joint->child_link_name +
                             "' is the child of joints '" + it->second + "' and '" + name +
                             "'; stiff models serial chains (a tree without loops)");
    }
  }

  auto find_link = [&](const std::string& name, const char* role) {
    urdf::LinkConstSharedPtr l = model->getLink(name);
    if (!l)
      throw ParseError(
          file, 0, 0, std::string("URDF has no link named '") + name + "' (the " + role + " link)");
    return l;
  };

  // The base: the named link, else `base_link`, else the root. It may be a frame fixed beside
  // the arm (ROS-Industrial `base` under `base_link`): the chain then starts at the anchor,
  // the highest link joined to the base by fixed joints only, and the base's pose in the
  // anchor is taken out of the first joint.
  urdf::LinkConstSharedPtr base =
      !base_link.empty() ? find_link(base_link, "base")
                         : (model->getLink("base_link") ? model->getLink("base_link") : root);
  urdf::LinkConstSharedPtr anchor = base;
  Eigen::Matrix4d anchor_to_base = Eigen::Matrix4d::Identity();
  while (anchor->parent_joint && anchor->parent_joint->type == urdf::Joint::FIXED &&
         anchor->getParent()) {
    anchor_to_base =
        urdf_pose(anchor->parent_joint->parent_to_joint_origin_transform) * anchor_to_base;
    anchor = anchor->getParent();
  }

  // Candidate tips: links below the anchor reached through revolute, continuous and fixed
  // joints only, with at least one moving joint on the way, none of whose children is also one.
  struct Candidate {
    urdf::LinkConstSharedPtr link;
    int moving;
  };
  std::vector<Candidate> reachable, maximal;
  {
    std::vector<Candidate> stack{{anchor, 0}};
    while (!stack.empty()) {
      const Candidate c = stack.back();
      stack.pop_back();
      bool extended = false;
      for (const auto& child : c.link->child_links) {
        if (!is_supported(*child->parent_joint)) continue;
        const Candidate next{child, c.moving + (is_moving(*child->parent_joint) ? 1 : 0)};
        stack.push_back(next);
        if (next.moving > 0) extended = true;
      }
      if (c.moving > 0) {
        reachable.push_back(c);
        if (!extended) maximal.push_back(c);
      }
    }
  }
  auto reachable_named = [&](const std::string& name) -> urdf::LinkConstSharedPtr {
    for (const auto& c : reachable)
      if (c.link->name == name) return c.link;
    return nullptr;
  };
  std::string tip_rule;
  urdf::LinkConstSharedPtr tip;
  if (!tip_link.empty()) {
    const auto named = find_link(tip_link, "tip");
    tip = reachable_named(tip_link);
    if (!tip) {
      // Say why: above the base, on another branch, or behind an unsupported joint.
      std::string why = "it is not below '" + anchor->name + "'";
      for (const auto& l : ancestry(anchor))
        if (l == named) why = "it is above the base link '" + base->name + "'";
      for (auto l = named; l && l != anchor; l = l->getParent())
        if (l->parent_joint && !is_supported(*l->parent_joint)) {
          why = "joint '" + l->parent_joint->name +
                "' on the way is not revolute, continuous or fixed";
          break;
        }
      throw ParseError(
          file, 0, 0,
          "URDF link '" + tip_link + "' cannot end a chain from '" + base->name + "': " + why);
    }
    tip_rule = "named";
  } else {
    for (const char* conventional : {"tool0", "flange"})
      if (!tip && (tip = reachable_named(conventional))) tip_rule = "the ROS-Industrial tool frame";
    if (!tip) {
      int most = 0;
      for (const auto& c : maximal) most = std::max(most, c.moving);
      std::vector<std::string> best, all;
      for (const auto& c : maximal) {
        all.push_back(c.link->name + " (" + std::to_string(c.moving) + " joints)");
        if (c.moving == most) {
          best.push_back(c.link->name);
          tip = c.link;
        }
      }
      if (maximal.empty())
        throw ParseError(file, 0, 0,
                         "URDF has no revolute or continuous joint below '" + anchor->name + "'");
      if (best.size() > 1)
        throw ParseError(
            file, 0, 0,
            "URDF chain from '" + base->name +
                "' has several possible tip links; name one (--tip): " + join_names(all));
      tip_rule = maximal.size() == 1 ? "the only end of the chain" : "the end with the most joints";
    }
  }

  std::vector<urdf::LinkConstSharedPtr> chain;
  for (auto l = tip; l != anchor; l = l->getParent()) chain.push_back(l);
  chain.push_back(anchor);
  std::reverse(chain.begin(), chain.end());

  RobotModel robot;
  robot.name = model->getName();
  robot.convention = Convention::urdf;
  robot.source_path = file;
  std::vector<std::string> notes;
  // Fixed transforms not yet assigned to a joint; the chain starts in the base frame.
  Eigen::Matrix4d pending = anchor_to_base.inverse();
  for (size_t i = 1; i < chain.size(); ++i) {
    const auto& joint = chain[i]->parent_joint;
    const Eigen::Matrix4d origin = urdf_pose(joint->parent_to_joint_origin_transform);
    Eigen::Vector3d axis(joint->axis.x, joint->axis.y, joint->axis.z);
    if (joint->type != urdf::Joint::FIXED) {
      if (axis.norm() < 1e-12)
        throw ParseError(file, 0, 0, "URDF joint '" + joint->name + "' has a zero axis");
      axis.normalize();
    }
    if (joint->type == urdf::Joint::FIXED) {
      pending = pending * origin;
    } else if (!is_moving(*joint)) {
      // lower = upper: the joint cannot move; it is a fixed transform at that angle.
      if (!std::isfinite(joint->limits->lower))
        throw ParseError(file, 0, 0,
                         "URDF joint '" + joint->name + "' is locked at a non-finite angle");
      Eigen::Matrix4d rot = Eigen::Matrix4d::Identity();
      rot.block<3, 3>(0, 0) = Eigen::AngleAxisd(joint->limits->lower, axis).toRotationMatrix();
      pending = pending * origin * rot;
      std::ostringstream n;
      n << "joint '" << joint->name << "' has lower = upper = " << joint->limits->lower
        << " rad: locked there (a fixed transform, not a joint)";
      notes.push_back(n.str());
    } else {
      Joint j;
      j.name = joint->name;
      j.pre = pending * origin;
      pending.setIdentity();
      j.axis = axis;
      if (joint->type == urdf::Joint::REVOLUTE && joint->limits) {
        j.lower = joint->limits->lower;
        j.upper = joint->limits->upper;
        j.effort = joint->limits->effort;
        j.velocity = joint->limits->velocity;
        if (!(j.lower < j.upper))
          throw ParseError(file, 0, 0, "URDF joint '" + joint->name + "' has lower > upper limit");
      } else if (joint->type == urdf::Joint::CONTINUOUS) {
        // No end stops: one turn either way reaches every angle from any start without
        // crossing a limit, and keeps ranges finite for sampling.
        j.lower = -2 * kPi;
        j.upper = 2 * kPi;
        if (joint->limits) {
          j.effort = joint->limits->effort;
          j.velocity = joint->limits->velocity;
        }
        notes.push_back("joint '" + joint->name +
                        "' is continuous: range [-2 pi, 2 pi] rad (one turn either way)");
      }
      for (double& v : j.dh) v = NAN;
      robot.joints.push_back(j);
    }
    if (const auto& inertial = chain[i]->inertial; inertial && !robot.joints.empty()) {
      // Express the link's centre of mass in the frame of the last moving joint.
      const Eigen::Matrix4d com = pending * urdf_pose(inertial->origin);
      auto& j = robot.joints.back();
      const double m = inertial->mass;
      if (m > 0) {
        j.com = (j.mass * j.com + m * com.block<3, 1>(0, 3)) / (j.mass + m);
        j.mass += m;
      }
    }
  }
  if (robot.joints.empty())
    throw ParseError(file, 0, 0,
                     "URDF chain '" + base->name + "' -> '" + tip->name + "' has no moving joint");
  if (robot.dof() > kMaxJoints)
    throw ParseError(file, 0, 0,
                     "URDF chain '" + base->name + "' -> '" + tip->name + "' has " +
                         std::to_string(robot.dof()) + " moving joints; at most " +
                         std::to_string(kMaxJoints) + " are supported");
  // Fixed transforms after the last joint define the flange: fold them into its `post`.
  auto& last = robot.joints.back();
  last.post = last.post * pending;
  if (last.mass > 0) {
    const Eigen::Vector4d c = pending.inverse() * last.com.homogeneous();
    last.com = c.head<3>();
  }
  if (report) {
    report->base_link = base->name;
    report->tip_link = tip->name;
    report->notes.clear();
    report->notes.push_back("chain: '" + base->name + "' -> '" + tip->name + "' (" +
                            std::to_string(robot.dof()) + " joints; tip: " + tip_rule + ")");
    if (anchor != base)
      report->notes.push_back("base '" + base->name + "' is fixed to '" + anchor->name +
                              "': poses are in '" + base->name + "'");
    std::vector<std::string> others;
    for (const auto& c : maximal)
      if (c.link != tip) others.push_back(c.link->name);
    if (!others.empty())
      report->notes.push_back("other chain ends, not used: " + join_names(others));
    for (auto& n : notes) report->notes.push_back(std::move(n));
  }
  return robot;
}

RobotModel load_robot(const std::string& path,
                      const RobotLoadOptions& options,
                      RobotFileReport* report) {
  const std::string text = read_text_file(path);
  // By content, not by name: a URDF is XML (.URDF, .xml and .urdf.xacro output alike), and a
  // YAML robot file never starts with '<'.
  size_t i = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
  while (i < text.size() && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  const bool urdf_file = i < text.size() && text[i] == '<';
  RobotFileReport local;
  RobotModel robot;
  if (urdf_file) {
    robot = parse_robot_urdf(text, path, options.tip_link, options.base_link, &local);
  } else {
    if (!options.base_link.empty() || !options.tip_link.empty())
      throw InvalidArgument(path +
                            ": a base or tip link selects a chain in a URDF file; a YAML robot "
                            "is one chain already");
    robot = parse_robot_yaml(text, path);
  }
  auto check_point = [&](const std::optional<Eigen::Vector3d>& p, const char* what) {
    if (p && !p->allFinite()) throw InvalidArgument(std::string(what) + " is not finite");
  };
  check_point(options.measured_point, "measured point");
  check_point(options.load_point, "load point");
  check_point(options.tool_com, "tool centre of mass");
  if (options.tool_mass && !(std::isfinite(*options.tool_mass) && *options.tool_mass >= 0))
    throw InvalidArgument("tool mass must be a finite number >= 0 kg");
  // A YAML file without load_point loads at its measured point; the same holds for options.
  const bool load_follows = robot.load_point == robot.measured_point;
  if (options.measured_point) {
    robot.measured_point = *options.measured_point;
    if (load_follows && !options.load_point) robot.load_point = robot.measured_point;
    local.notes.push_back("measured point set by the user");
  }
  if (options.load_point) {
    robot.load_point = *options.load_point;
    local.notes.push_back("load point set by the user");
  }
  if (options.tool_mass) robot.tool_mass = *options.tool_mass;
  if (options.tool_com) robot.tool_com = *options.tool_com;
  if (options.tool_mass || options.tool_com) local.notes.push_back("tool set by the user");
  if (report) *report = std::move(local);
  return robot;
}

namespace {
/// A YAML double-quoted scalar: names may hold quotes, backslashes or control characters
/// (anything the reader accepted must be written back readable).
std::string yaml_quoted(const std::string& s) {
  std::string q = "\"";
  for (const unsigned char c : s) {
    if (c == '"' || c == '\\') {
      q += '\\';
      q += static_cast<char>(c);
    } else if (c < 0x20 || c == 0x7f) {
      static const char hex[] = "0123456789abcdef";
      q += "\\x";
      q += hex[c >> 4];
      q += hex[c & 0xf];
    } else {
      q += static_cast<char>(c);
    }
  }
  return q + "\"";
}
}  // namespace

std::string robot_to_yaml(const RobotModel& robot) {
  std::ostringstream o;
  o << std::setprecision(17);
  auto vec = [&](const Eigen::Vector3d& v) {
    o << "[" << v(0) << ", " << v(1) << ", " << v(2) << "]";
  };
  o << "name: " << yaml_quoted(robot.name) << "\n";
  o << "units: {length: m, angle: rad}\n";
  const bool dh = robot.convention != Convention::urdf;
  o << "convention: " << (dh ? to_string(robot.convention) : "general") << "\n";
  o << "joints:\n";
  for (const auto& j : robot.joints) {
    o << "  - name: " << yaml_quoted(j.name) << "\n";
    if (dh) {
      o << "    alpha: " << j.dh[0] << "\n    a: " << j.dh[1] << "\n    d: " << j.dh[2]
        << "\n    theta_offset: " << j.dh[3] << "\n";
    } else {
      o << "    pre: [";
      for (int k = 0; k < 16; ++k) o << (k ? ", " : "") << j.pre(k / 4, k % 4);
      o << "]\n    axis: ";
      vec(j.axis);
      o << "\n    post: [";
      for (int k = 0; k < 16; ++k) o << (k ? ", " : "") << j.post(k / 4, k % 4);
      o << "]\n";
    }
    o << "    limits: [" << j.lower << ", " << j.upper << "]\n";
    if (j.mass > 0) {
      o << "    mass: " << j.mass << "\n    com: ";
      vec(j.com);
      o << "\n";
    }
  }
  o << "measured_point: ";
  vec(robot.measured_point);
  o << "\nload_point: ";
  vec(robot.load_point);
  o << "\ntool: {mass: " << robot.tool_mass << ", com: ";
  vec(robot.tool_com);
  o << "}\ngravity: ";
  vec(robot.gravity);
  o << "\n";
  return o.str();
}

}  // namespace stiff

namespace stiff {
namespace {

/// Text inside an XML comment: no "--", no trailing '-', no characters XML cannot hold.
std::string xml_comment_text(const std::string& s) {
  std::string o;
  for (const unsigned char c : s) {
    if (c == '-' && !o.empty() && o.back() == '-') o += ' ';
    o += (c < 0x20 && c != '\t') ? ' ' : static_cast<char>(c);
  }
  if (!o.empty() && o.back() == '-') o += ' ';
  return o;
}

void require_rigid(const Eigen::Matrix4d& t, const std::string& what) {
  const Eigen::Matrix3d r = t.topLeftCorner<3, 3>();
  if (!t.allFinite() || (r.transpose() * r - Eigen::Matrix3d::Identity()).norm() > 1e-9 ||
      r.determinant() < 0 || t.row(3) != Eigen::RowVector4d(0, 0, 0, 1))
    throw InvalidArgument(what + " is not a finite rigid transform (rotation and translation)");
}

/// URDF origin angles: R = Rz(yaw) Ry(pitch) Rx(roll) (fixed axes x, y, z). Roll is taken
/// from what remains once pitch and yaw are removed, so that near pitch = +-pi/2, where roll
/// and yaw only count together, the product still reproduces R to rounding.
Eigen::Vector3d urdf_rpy(const Eigen::Matrix3d& r) {
  const double pitch = std::atan2(-r(2, 0), std::hypot(r(0, 0), r(1, 0)));
  const double yaw = std::hypot(r(0, 0), r(1, 0)) > 1e-12 ? std::atan2(r(1, 0), r(0, 0)) : 0.0;
  const Eigen::Matrix3d rest = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()))
                                   .toRotationMatrix()
                                   .transpose() *
                               r;
  const double roll = std::atan2(rest(2, 1), rest(1, 1));
  return {roll, pitch, yaw};
}

}  // namespace

std::string robot_to_urdf(const RobotModel& robot, const UrdfWriteOptions& options) {
  const int n = robot.dof();
  if (n == 0) throw InvalidArgument("URDF export: the robot has no joint");
  for (int j = 0; j < n; ++j) {
    const Joint& jt = robot.joints[j];
    const std::string where =
        "URDF export: joint " + std::to_string(j + 1) + " ('" + jt.name + "')";
    require_rigid(jt.pre, where + " fixed transform before the joint");
    require_rigid(jt.post, where + " fixed transform after the joint");
    if (!jt.axis.allFinite() || jt.axis.norm() < 1e-12)
      throw InvalidArgument(where + " has no finite axis");
    if (!std::isfinite(jt.lower) || !std::isfinite(jt.upper) || !(jt.lower < jt.upper))
      throw InvalidArgument(where + " limits are not a finite range");
    if (!std::isfinite(jt.mass) || jt.mass < 0 || !jt.com.allFinite())
      throw InvalidArgument(where + " mass or centre of mass is not finite");
  }
  if (!robot.measured_point.allFinite() || !robot.tool_com.allFinite() ||
      !std::isfinite(robot.tool_mass) || robot.tool_mass < 0)
    throw InvalidArgument("URDF export: the measured point or the tool is not finite");
  if (options.world_from_base) require_rigid(*options.world_from_base, "URDF export: world pose");

  // Names the robot's joints already take: a generated joint never shares one (URDF joint
  // names are unique).
  std::set<std::string> used;
  std::vector<std::string> names(n);
  for (int j = 0; j < n; ++j) {
    const std::string base =
        robot.joints[j].name.empty() ? "joint" + std::to_string(j + 1) : robot.joints[j].name;
    std::string name = base;
    for (int k = 2; used.count(name); ++k) name = base + "_" + std::to_string(k);
    used.insert(name);
    names[j] = name;
  }
  auto fresh = [&](const std::string& base) {
    std::string name = base;
    for (int k = 2; used.count(name); ++k) name = base + "_" + std::to_string(k);
    used.insert(name);
    return name;
  };

  std::ostringstream o;
  o << std::setprecision(17);
  auto origin = [&](const Eigen::Matrix4d& t) {
    const Eigen::Vector3d p = t.topRightCorner<3, 1>();
    const Eigen::Vector3d rpy = urdf_rpy(t.topLeftCorner<3, 3>());
    o << "    <origin xyz=\"" << p(0) << " " << p(1) << " " << p(2) << "\" rpy=\"" << rpy(0) << " "
      << rpy(1) << " " << rpy(2) << "\"/>\n";
  };
  // A point mass: stiff's links carry a mass and a centre of mass, no inertia tensor.
  auto inertial = [&](double mass, const Eigen::Vector3d& com) {
    if (!(mass > 0)) return;
    o << "    <inertial>\n      <origin xyz=\"" << com(0) << " " << com(1) << " " << com(2)
      << "\" rpy=\"0 0 0\"/>\n      <mass value=\"" << mass
      << "\"/>\n      <inertia ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"/>\n"
      << "    </inertial>\n";
  };
  auto fixed_joint = [&](const std::string& name, const std::string& parent,
                         const std::string& child, const Eigen::Matrix4d& t) {
    o << "  <joint name=\"" << xml_attribute(name) << "\" type=\"fixed\">\n    <parent link=\""
      << parent << "\"/>\n    <child link=\"" << child << "\"/>\n";
    origin(t);
    o << "  </joint>\n";
  };

  o << "<?xml version=\"1.0\"?>\n";
  for (const auto& c : options.comments) o << "<!-- " << xml_comment_text(c) << " -->\n";
  o << "<robot name=\"" << xml_attribute(robot.name.empty() ? "robot" : robot.name) << "\">\n";
  if (options.world_from_base) {
    o << "  <link name=\"world\"/>\n";
    fixed_joint(fresh("world_joint"), "world", "base_link", *options.world_from_base);
  }
  o << "  <link name=\"base_link\"/>\n";
  Eigen::Matrix4d before = Eigen::Matrix4d::Identity();  // post of the previous joint
  std::string parent = "base_link";
  for (int j = 0; j < n; ++j) {
    const Joint& jt = robot.joints[j];
    const std::string child = "link_" + std::to_string(j + 1);
    o << "  <joint name=\"" << xml_attribute(names[j]) << "\" type=\"revolute\">\n"
      << "    <parent link=\"" << parent << "\"/>\n    <child link=\"" << child << "\"/>\n";
    origin(before * jt.pre);
    const Eigen::Vector3d a = jt.axis.normalized();
    o << "    <axis xyz=\"" << a(0) << " " << a(1) << " " << a(2) << "\"/>\n"
      << "    <limit lower=\"" << jt.lower << "\" upper=\"" << jt.upper << "\" effort=\""
      << jt.effort << "\" velocity=\"" << jt.velocity << "\"/>\n  </joint>\n";
    // stiff's link frame is after `post`, the URDF link frame before it.
    o << "  <link name=\"" << child << "\">\n";
    inertial(jt.mass, (jt.post * jt.com.homogeneous()).head<3>());
    o << "  </link>\n";
    before = jt.post;
    parent = child;
  }
  fixed_joint(fresh("flange_joint"), parent, "tool0", before);
  o << "  <link name=\"tool0\">\n";
  inertial(robot.tool_mass, robot.tool_com);
  o << "  </link>\n";
  Eigen::Matrix4d tcp = Eigen::Matrix4d::Identity();
  tcp.topRightCorner<3, 1>() = robot.measured_point;
  fixed_joint(fresh("tcp_joint"), "tool0", "tcp", tcp);
  o << "  <link name=\"tcp\"/>\n</robot>\n";
  return o.str();
}

}  // namespace stiff
