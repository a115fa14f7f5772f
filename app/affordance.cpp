#include "app/affordance.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

#include <Eigen/Cholesky>

#include "common/check.h"

namespace toolbench::app {
namespace {

constexpr const char* kFormat = "toolbench-affordance-gp";
constexpr int kVersion = 1;

double SquaredExp(const Eigen::VectorXd& a, const Eigen::VectorXd& b, double length_scale, double signal_var) {
  return signal_var * std::exp(-0.5 * (a - b).squaredNorm() / (length_scale * length_scale));
}

Eigen::MatrixXd Gram(const Eigen::MatrixXd& X, double length_scale, double signal_var) {
  const Eigen::Index n = X.rows();
  Eigen::MatrixXd K(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = 0; j <= i; ++j) {
      K(i, j) = K(j, i) = SquaredExp(X.row(i).transpose(), X.row(j).transpose(), length_scale, signal_var);
    }
  }
  return K;
}

nlohmann::json VecJson(const Eigen::VectorXd& v) { return std::vector<double>(v.data(), v.data() + v.size()); }

Eigen::VectorXd VecFrom(const nlohmann::json& j, const std::string& what) {
  if (!j.is_array()) ThrowInvalid(what, " is not an array");
  Eigen::VectorXd v(static_cast<Eigen::Index>(j.size()));
  for (std::size_t i = 0; i < j.size(); ++i) {
    if (!j[i].is_number()) ThrowInvalid(what, "[", i, "] is not a number");
    v[static_cast<Eigen::Index>(i)] = j[i].get<double>();
  }
  if (!v.allFinite()) ThrowInvalid(what, " holds a non-finite number");
  return v;
}

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? std::nan("") : s / static_cast<double>(v.size());
}

double Correlation(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() < 3 || a.size() != b.size()) return std::nan("");
  const double ma = Mean(a), mb = Mean(b);
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  if (saa <= 0 || sbb <= 0) return std::nan("");
  return sab / std::sqrt(saa * sbb);
}

}  // namespace

const std::vector<std::string>& AffordanceFeatureNames() {
  static const std::vector<std::string> kNames = {
      "total_length",   "handle_length",  "handle_radius",  "effector_x_T",   "effector_z_T",
      "effector_size_x", "effector_size_y", "effector_size_z", "effector_protrusion", "effector_sq_a1",
      "effector_sq_a2", "effector_sq_a3", "effector_sq_e1", "effector_sq_e2", "effector_x_G",
      "effector_y_G",   "effector_z_G",   "working_x_G",    "working_y_G",    "working_z_G"};
  return kNames;
}

Eigen::VectorXd AffordanceFeatures(const std::vector<perception::Part>& parts, int handle_part,
                                   const perception::ToolFeatures& f, const Eigen::Isometry3d& X_GT) {
  if (handle_part < 0 || handle_part >= static_cast<int>(parts.size())) {
    ThrowInvalid("AffordanceFeatures: handle_part = ", handle_part, " (expected an index into the ", parts.size(),
                 " parts)");
  }
  if (!X_GT.matrix().allFinite()) ThrowInvalid("AffordanceFeatures: X_GT is not finite");
  if (!(std::isfinite(f.total_length) && std::isfinite(f.handle_length) && std::isfinite(f.handle_radius) &&
        f.effector_center.allFinite() && f.effector_size.allFinite() && std::isfinite(f.effector_protrusion))) {
    ThrowInvalid("AffordanceFeatures: the tool features are not finite");
  }
  // The effector part: the largest part that is not the handle (by surface points).
  int effector = -1;
  for (int i = 0; i < static_cast<int>(parts.size()); ++i) {
    if (i == handle_part) continue;
    if (effector < 0 || parts[i].points.cols() > parts[effector].points.cols()) effector = i;
  }
  Eigen::Vector3d sq_size = Eigen::Vector3d::Zero();
  double e1 = 1.0, e2 = 1.0;
  if (effector >= 0) {
    const perception::Superquadric& sq = parts[effector].sq;
    sq_size = sq.size;
    std::sort(sq_size.data(), sq_size.data() + 3, std::greater<>());
    e1 = sq.e1;
    e2 = sq.e2;
  }
  const Eigen::Vector3d p_GE = X_GT * f.effector_center;
  const Eigen::Vector3d w_G = X_GT.linear() * Eigen::Vector3d::UnitX();
  Eigen::VectorXd x(static_cast<Eigen::Index>(AffordanceFeatureNames().size()));
  x << f.total_length, f.handle_length, f.handle_radius, f.effector_center.x(), f.effector_center.z(),
      f.effector_size.x(), f.effector_size.y(), f.effector_size.z(), f.effector_protrusion, sq_size[0], sq_size[1],
      sq_size[2], e1, e2, p_GE.x(), p_GE.y(), p_GE.z(), w_G.x(), w_G.y(), w_G.z();
  if (!x.allFinite()) ThrowInvalid("AffordanceFeatures: the effector superquadric is not finite");
  return x;
}

Eigen::Isometry3d HeldToolPose(const Eigen::Isometry3d& X_TH, double roll_rad) {
  if (!X_TH.matrix().allFinite() || !std::isfinite(roll_rad)) {
    ThrowInvalid("HeldToolPose: X_TH or roll_rad = ", roll_rad, " is not finite");
  }
  Eigen::Isometry3d R = Eigen::Isometry3d::Identity();
  R.linear() = Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return R * X_TH.inverse();
}

std::vector<AffordanceSample> ReadAffordanceSamples(const std::filesystem::path& results_jsonl) {
  std::ifstream in(results_jsonl);
  if (!in) ThrowInvalid("ReadAffordanceSamples: cannot open '", results_jsonl.string(), "'");
  const std::size_t d = AffordanceFeatureNames().size();
  std::vector<std::pair<std::string, AffordanceSample>> read;  // by trial id
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const std::string where = Cat(results_jsonl.string(), ":", number);
    try {
      const nlohmann::json j = nlohmann::json::parse(line);
      if (!j.value("ok", false)) continue;
      const nlohmann::json& r = j.at("result");
      if (!r.at("labelled").get<bool>()) continue;
      AffordanceSample s;
      s.tool = r.at("tool").get<std::string>();
      s.family = r.at("family").get<std::string>();
      s.action = r.at("action").get<std::string>();
      s.x = VecFrom(r.at("features"), "features");
      if (static_cast<std::size_t>(s.x.size()) != d) {
        ThrowInvalid("features has ", s.x.size(), " values (expected ", d, ")");
      }
      s.displacement_m = r.at("displacement_along_m").get<double>();
      if (!std::isfinite(s.displacement_m)) ThrowInvalid("displacement_along_m is not finite");
      read.emplace_back(j.at("id").get<std::string>(), std::move(s));
    } catch (const std::invalid_argument& e) {
      ThrowInvalid("ReadAffordanceSamples: ", where, ": ", e.what());
    } catch (const nlohmann::json::exception& e) {
      ThrowInvalid("ReadAffordanceSamples: ", where, ": ", e.what());
    }
  }
  // Trials finish in any order when run in parallel: order by id so that the same trials give
  // the same model, bit for bit.
  std::stable_sort(read.begin(), read.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<AffordanceSample> out;
  for (auto& [id, s] : read) out.push_back(std::move(s));
  return out;
}

void AffordanceTrainOptions::Validate() const {
  auto positive = [](const std::vector<double>& v, const char* name) {
    if (v.empty()) ThrowInvalid("AffordanceTrainOptions: ", name, " is empty");
    for (double x : v) {
      if (!(x > 0) || !std::isfinite(x)) ThrowInvalid("AffordanceTrainOptions: ", name, " holds ", x, " (expected > 0)");
    }
  };
  positive(length_scales, "length_scales");
  positive(signal_fractions, "signal_fractions");
  positive(noise_fractions, "noise_fractions");
  if (!(min_feature_scale > 0)) {
    ThrowInvalid("AffordanceTrainOptions: min_feature_scale = ", min_feature_scale, " (expected > 0)");
  }
}

void AffordanceModel::Factor(ActionGp& gp) {
  const Eigen::Index n = gp.X.rows();
  Eigen::MatrixXd K = Gram(gp.X, gp.length_scale, gp.signal_var);
  K.diagonal().array() += gp.noise_var;
  const Eigen::LLT<Eigen::MatrixXd> llt(K);
  if (llt.info() != Eigen::Success) ThrowInvalid("AffordanceModel: the kernel matrix is not positive definite");
  gp.L = llt.matrixL();
  const Eigen::VectorXd r = gp.y.array() - gp.y_mean;
  gp.alpha = llt.solve(r);
  gp.log_likelihood = -0.5 * r.dot(gp.alpha) - gp.L.diagonal().array().log().sum() -
                      0.5 * static_cast<double>(n) * std::log(2 * M_PI);
}

AffordanceModel AffordanceModel::Train(const std::vector<AffordanceSample>& samples,
                                       const AffordanceTrainOptions& options) {
  options.Validate();
  const Eigen::Index d = static_cast<Eigen::Index>(AffordanceFeatureNames().size());
  std::map<std::string, std::vector<const AffordanceSample*>> by_action;
  for (const AffordanceSample& s : samples) {
    if (s.x.size() != d) ThrowInvalid("AffordanceModel::Train: a sample of ", s.tool, " has ", s.x.size(),
                                      " features (expected ", d, ")");
    if (!s.x.allFinite() || !std::isfinite(s.displacement_m)) {
      ThrowInvalid("AffordanceModel::Train: a sample of ", s.tool, " (", s.action, ") is not finite");
    }
    by_action[s.action].push_back(&s);
  }
  if (by_action.empty()) ThrowInvalid("AffordanceModel::Train: no samples");
  AffordanceModel model;
  for (const auto& [action, rows] : by_action) {
    const Eigen::Index n = static_cast<Eigen::Index>(rows.size());
    if (n < 2) ThrowInvalid("AffordanceModel::Train: action '", action, "' has ", n, " sample (expected >= 2)");
    ActionGp gp;
    Eigen::MatrixXd raw(n, d);
    gp.y.resize(n);
    for (Eigen::Index i = 0; i < n; ++i) {
      raw.row(i) = rows[static_cast<std::size_t>(i)]->x.transpose();
      gp.y[i] = rows[static_cast<std::size_t>(i)]->displacement_m;
      gp.tools.push_back(rows[static_cast<std::size_t>(i)]->tool);
    }
    gp.x_mean = raw.colwise().mean().transpose();
    gp.x_scale.resize(d);
    for (Eigen::Index k = 0; k < d; ++k) {
      const double var = (raw.col(k).array() - gp.x_mean[k]).square().mean();
      gp.x_scale[k] = std::max(std::sqrt(var), options.min_feature_scale);
    }
    gp.X = (raw.rowwise() - gp.x_mean.transpose()).array().rowwise() / gp.x_scale.transpose().array();
    gp.y_mean = gp.y.mean();
    // A floor keeps the grid meaningful when every trial of an action gave (almost) the same result.
    const double y_var = std::max((gp.y.array() - gp.y_mean).square().mean(), 1e-6);
    // Squared distances once; the kernel for each length scale once; then only the Cholesky
    // factorisations per (signal, noise) pair.
    Eigen::MatrixXd D2(n, n);
    for (Eigen::Index i = 0; i < n; ++i) {
      for (Eigen::Index j = 0; j <= i; ++j) D2(i, j) = D2(j, i) = (gp.X.row(i) - gp.X.row(j)).squaredNorm();
    }
    const Eigen::VectorXd r = gp.y.array() - gp.y_mean;
    double best_ll = -std::numeric_limits<double>::infinity();
    double best_l = 0, best_sf = 0, best_sn = 0;
    for (double l : options.length_scales) {
      const Eigen::MatrixXd base = (-0.5 * D2.array() / (l * l)).exp().matrix();
      for (double sf : options.signal_fractions) {
        for (double sn : options.noise_fractions) {
          Eigen::MatrixXd K = sf * y_var * base;
          K.diagonal().array() += sn * y_var;
          const Eigen::LLT<Eigen::MatrixXd> llt(K);
          if (llt.info() != Eigen::Success) continue;
          const Eigen::MatrixXd& L = llt.matrixLLT();
          const double ll = -0.5 * r.dot(llt.solve(r)) - L.diagonal().array().log().sum() -
                            0.5 * static_cast<double>(n) * std::log(2 * M_PI);
          if (ll > best_ll) {
            best_ll = ll;
            best_l = l;
            best_sf = sf;
            best_sn = sn;
          }
        }
      }
    }
    if (!std::isfinite(best_ll)) ThrowInvalid("AffordanceModel::Train: no hyper-parameters give a usable kernel for '", action, "'");
    ActionGp best = std::move(gp);
    best.length_scale = best_l;
    best.signal_var = best_sf * y_var;
    best.noise_var = best_sn * y_var;
    Factor(best);
    model.gps_[action] = std::move(best);
  }
  return model;
}

AffordancePrediction AffordanceModel::Predict(std::string_view action, const Eigen::VectorXd& x) const {
  const auto it = gps_.find(action);
  if (it == gps_.end()) {
    std::string known;
    for (const auto& [name, gp] : gps_) known += (known.empty() ? "" : ", ") + name;
    ThrowInvalid("AffordanceModel::Predict: action '", action, "' was not explored (the model knows: ", known, ")");
  }
  const ActionGp& gp = it->second;
  if (x.size() != gp.x_mean.size()) {
    ThrowInvalid("AffordanceModel::Predict: x has ", x.size(), " features (expected ", gp.x_mean.size(), ")");
  }
  if (!x.allFinite()) ThrowInvalid("AffordanceModel::Predict: x is not finite");
  const Eigen::VectorXd z = (x - gp.x_mean).array() / gp.x_scale.array();
  Eigen::VectorXd k(gp.X.rows());
  for (Eigen::Index i = 0; i < gp.X.rows(); ++i) k[i] = SquaredExp(gp.X.row(i).transpose(), z, gp.length_scale, gp.signal_var);
  AffordancePrediction p;
  p.displacement_m = gp.y_mean + k.dot(gp.alpha);
  const Eigen::VectorXd v = gp.L.triangularView<Eigen::Lower>().solve(k);
  p.std_m = std::sqrt(std::max(0.0, gp.signal_var - v.squaredNorm()));
  return p;
}

bool AffordanceModel::HasAction(std::string_view action) const { return gps_.find(action) != gps_.end(); }

std::vector<std::string> AffordanceModel::actions() const {
  std::vector<std::string> out;
  for (const auto& [name, gp] : gps_) out.push_back(name);
  return out;
}

int AffordanceModel::samples(std::string_view action) const {
  const auto it = gps_.find(action);
  return it == gps_.end() ? 0 : static_cast<int>(it->second.X.rows());
}

nlohmann::json AffordanceModel::ToJson() const {
  nlohmann::json j;
  j["format"] = kFormat;
  j["version"] = kVersion;
  j["regressor"] =
      "Gaussian process per action, squared-exponential kernel on standardised features, hyper-parameters by "
      "largest log marginal likelihood on a grid; target: ball displacement along the action's direction [m]";
  j["feature_names"] = AffordanceFeatureNames();
  j["info"] = info;
  j["actions"] = nlohmann::json::object();
  for (const auto& [name, gp] : gps_) {
    nlohmann::json a;
    a["samples"] = gp.X.rows();
    a["length_scale"] = gp.length_scale;
    a["signal_var"] = gp.signal_var;
    a["noise_var"] = gp.noise_var;
    a["log_marginal_likelihood"] = gp.log_likelihood;
    a["x_mean"] = VecJson(gp.x_mean);
    a["x_scale"] = VecJson(gp.x_scale);
    a["y_mean"] = gp.y_mean;
    a["targets"] = VecJson(gp.y);
    a["tools"] = gp.tools;
    a["inputs"] = nlohmann::json::array();
    for (Eigen::Index i = 0; i < gp.X.rows(); ++i) a["inputs"].push_back(VecJson(gp.X.row(i).transpose()));
    j["actions"][name] = a;
  }
  return j;
}

void AffordanceModel::Save(const std::filesystem::path& file) const {
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
  std::ofstream out(file);
  if (!out) throw std::runtime_error("AffordanceModel::Save: cannot write '" + file.string() + "'");
  out << ToJson().dump(1) << "\n";
  if (!out) throw std::runtime_error("AffordanceModel::Save: writing '" + file.string() + "' failed");
}

AffordanceModel AffordanceModel::Load(const std::filesystem::path& file) {
  const std::string where = "AffordanceModel::Load: '" + file.string() + "'";
  std::ifstream in(file);
  if (!in) ThrowInvalid(where, ": cannot open (missing or unreadable); make one with `toolbench explore`");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    ThrowInvalid(where, ": not JSON (", e.what(), ")");
  }
  AffordanceModel model;
  try {
    if (!j.is_object() || j.value("format", "") != kFormat) {
      ThrowInvalid("format is not '", kFormat, "'");
    }
    if (j.at("version").get<int>() != kVersion) {
      ThrowInvalid("version ", j.at("version").get<int>(), " (this build reads ", kVersion, ")");
    }
    if (j.at("feature_names").get<std::vector<std::string>>() != AffordanceFeatureNames()) {
      ThrowInvalid("made for other features than this build extracts (feature_names differ)");
    }
    model.info = j.value("info", nlohmann::json::object());
    const Eigen::Index d = static_cast<Eigen::Index>(AffordanceFeatureNames().size());
    if (!j.at("actions").is_object() || j.at("actions").empty()) ThrowInvalid("no actions");
    for (const auto& [name, a] : j.at("actions").items()) {
      const std::string what = "actions." + name;
      ActionGp gp;
      gp.length_scale = a.at("length_scale").get<double>();
      gp.signal_var = a.at("signal_var").get<double>();
      gp.noise_var = a.at("noise_var").get<double>();
      if (!(gp.length_scale > 0 && gp.signal_var > 0 && gp.noise_var > 0) || !std::isfinite(gp.length_scale) ||
          !std::isfinite(gp.signal_var) || !std::isfinite(gp.noise_var)) {
        ThrowInvalid(what, ": length_scale, signal_var and noise_var must be finite and > 0");
      }
      gp.x_mean = VecFrom(a.at("x_mean"), what + ".x_mean");
      gp.x_scale = VecFrom(a.at("x_scale"), what + ".x_scale");
      gp.y_mean = a.at("y_mean").get<double>();
      gp.y = VecFrom(a.at("targets"), what + ".targets");
      gp.tools = a.at("tools").get<std::vector<std::string>>();
      if (gp.x_mean.size() != d || gp.x_scale.size() != d) ThrowInvalid(what, ": x_mean/x_scale need ", d, " values");
      if ((gp.x_scale.array() <= 0).any()) ThrowInvalid(what, ": x_scale must be > 0");
      const nlohmann::json& inputs = a.at("inputs");
      const Eigen::Index n = gp.y.size();
      if (n < 1 || static_cast<Eigen::Index>(inputs.size()) != n || static_cast<Eigen::Index>(gp.tools.size()) != n) {
        ThrowInvalid(what, ": inputs (", inputs.size(), "), targets (", n, ") and tools (", gp.tools.size(),
                     ") must have the same, non-zero length");
      }
      gp.X.resize(n, d);
      for (Eigen::Index i = 0; i < n; ++i) {
        const Eigen::VectorXd row = VecFrom(inputs[static_cast<std::size_t>(i)], Cat(what, ".inputs[", i, "]"));
        if (row.size() != d) ThrowInvalid(what, ".inputs[", i, "] has ", row.size(), " values (expected ", d, ")");
        gp.X.row(i) = row.transpose();
      }
      Factor(gp);
      model.gps_[name] = std::move(gp);
    }
  } catch (const nlohmann::json::exception& e) {
    ThrowInvalid(where, ": ", e.what());
  } catch (const std::invalid_argument& e) {
    ThrowInvalid(where, ": ", e.what());
  }
  return model;
}

HeldOutReport EvaluateHeldOut(const std::vector<AffordanceSample>& samples, HoldOut by,
                              const AffordanceTrainOptions& options) {
  auto group_of = [&](const AffordanceSample& s) { return by == HoldOut::kFamily ? s.family : s.tool; };
  std::set<std::string> groups;
  for (const AffordanceSample& s : samples) groups.insert(group_of(s));
  if (groups.size() < 2) {
    ThrowInvalid("EvaluateHeldOut: ", groups.size(), " ", by == HoldOut::kFamily ? "family" : "tool",
                 " group(s) (expected >= 2 to leave one out)");
  }
  struct Errors {
    std::vector<double> model, mean;
    std::set<std::string> groups;
    std::vector<double> group_pred, group_true;  // per (group) means
  };
  std::map<std::string, Errors> per_action;
  Errors all;
  for (const std::string& g : groups) {
    std::vector<AffordanceSample> train;
    std::vector<const AffordanceSample*> test;
    for (const AffordanceSample& s : samples) {
      if (group_of(s) == g) {
        test.push_back(&s);
      } else {
        train.push_back(s);
      }
    }
    std::map<std::string, std::vector<double>> train_y;
    for (const AffordanceSample& s : train) train_y[s.action].push_back(s.displacement_m);
    std::vector<AffordanceSample> usable;
    for (const AffordanceSample& s : train) {
      if (train_y[s.action].size() >= 2) usable.push_back(s);
    }
    if (usable.empty()) continue;
    const AffordanceModel model = AffordanceModel::Train(usable, options);
    std::map<std::string, std::pair<std::vector<double>, std::vector<double>>> fold;  // action -> (pred, true)
    for (const AffordanceSample* s : test) {
      if (!model.HasAction(s->action)) continue;
      const double pred = model.Predict(s->action, s->x).displacement_m;
      const double base = Mean(train_y[s->action]);
      for (Errors* e : {&per_action[s->action], &all}) {
        e->model.push_back(pred - s->displacement_m);
        e->mean.push_back(base - s->displacement_m);
        e->groups.insert(g);
      }
      fold[s->action].first.push_back(pred);
      fold[s->action].second.push_back(s->displacement_m);
    }
    for (const auto& [action, pt] : fold) {
      per_action[action].group_pred.push_back(Mean(pt.first));
      per_action[action].group_true.push_back(Mean(pt.second));
    }
  }
  auto score = [](const std::string& action, const Errors& e) {
    HeldOutScore s;
    s.action = action;
    s.samples = static_cast<int>(e.model.size());
    s.groups = static_cast<int>(e.groups.size());
    for (std::size_t i = 0; i < e.model.size(); ++i) {
      s.mae_model_m += std::abs(e.model[i]);
      s.mae_mean_m += std::abs(e.mean[i]);
      s.rmse_model_m += e.model[i] * e.model[i];
      s.rmse_mean_m += e.mean[i] * e.mean[i];
    }
    const double n = std::max<double>(1.0, static_cast<double>(e.model.size()));
    s.mae_model_m /= n;
    s.mae_mean_m /= n;
    s.rmse_model_m = std::sqrt(s.rmse_model_m / n);
    s.rmse_mean_m = std::sqrt(s.rmse_mean_m / n);
    s.group_correlation = Correlation(e.group_pred, e.group_true);
    return s;
  };
  HeldOutReport report;
  report.by = by;
  for (const auto& [action, e] : per_action) report.per_action.push_back(score(action, e));
  report.overall = score("all", all);
  report.overall.group_correlation = std::nan("");
  return report;
}

nlohmann::json HeldOutJson(const HeldOutReport& report) {
  auto row = [](const HeldOutScore& s) {
    auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    return nlohmann::json{{"action", s.action},
                          {"samples", s.samples},
                          {"groups", s.groups},
                          {"mae_model_m", num(s.mae_model_m)},
                          {"mae_mean_m", num(s.mae_mean_m)},
                          {"rmse_model_m", num(s.rmse_model_m)},
                          {"rmse_mean_m", num(s.rmse_mean_m)},
                          {"mae_ratio", s.mae_mean_m > 0 ? num(s.mae_model_m / s.mae_mean_m) : nullptr},
                          {"group_correlation", num(s.group_correlation)}};
  };
  nlohmann::json j;
  j["held_out"] = report.by == HoldOut::kFamily ? "family" : "tool";
  j["baseline"] = "always predict the mean displacement of the action over the training fold";
  j["overall"] = row(report.overall);
  j["per_action"] = nlohmann::json::array();
  for (const HeldOutScore& s : report.per_action) j["per_action"].push_back(row(s));
  return j;
}

}  // namespace toolbench::app
