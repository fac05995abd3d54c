// `isostream tets --json`: the reference tetrahedra as computed at start-up, for inspection.
#include <iostream>
#include <nlohmann/json.hpp>

#include "server/cli/commands.h"
#include "server/hierarchy/reference_tets.h"

namespace isostream::cli {
namespace {

nlohmann::json Vec(const glm::ivec3& v) { return {v.x, v.y, v.z}; }
// + 0.0 turns a -0.0 (a normal's zero component, negated) into 0 for the reader.
nlohmann::json Vec(const glm::dvec3& v) { return {v.x + 0.0, v.y + 0.0, v.z + 0.0}; }

void PrintTets(bool json) {
  const ReferenceTets& tables = ReferenceTets::Get();
  nlohmann::json out;
  nlohmann::json classes = nlohmann::json::array();
  for (size_t c = 0; c < tables.all().size(); ++c) {
    const ReferenceTet& t = tables.all()[c];
    nlohmann::json j;
    j["id"] = c;
    j["level_mod3"] = t.level_mod3;
    j["vertices"] = {Vec(t.vertex[0]), Vec(t.vertex[1]), Vec(t.vertex[2]), Vec(t.vertex[3])};
    j["refinement_edge"] = {0, 3};
    j["refinement_vertex"] = Vec((t.vertex[0] + t.vertex[3]) / 2);
    j["children"] = {t.child[0].value, t.child[1].value};
    j["child_points"] = {t.child_point[0], t.child_point[1]};
    j["plane_normal"] = Vec(t.plane_normal);
    j["gradient_update"] = {Vec(t.gradient_update[0]), Vec(t.gradient_update[1])};
    classes.push_back(j);
  }
  out["note"] =
      "vertices normalised to the tet's bounding box in units of half its largest extent; "
      "child_points index the parent's vertices 0-3 and its refinement vertex 4";
  out["classes"] = classes;
  nlohmann::json initial = nlohmann::json::array();
  for (int i = 0; i < kNumInitialTets; ++i) initial.push_back(tables.initial_class(i).value);
  out["initial"] = initial;
  if (json) {
    std::cout << out.dump(2) << "\n";
    return;
  }
  std::cout << "id lvl%3  children  plane normal            vertices\n";
  for (const auto& j : classes)
    std::cout << j["id"] << "  " << j["level_mod3"] << "  " << j["children"].dump() << "  "
              << j["plane_normal"].dump() << "  " << j["vertices"].dump() << "\n";
}

}  // namespace

CLI::App* AddTetsCommand(CLI::App& app, int* exit_code) {
  auto* cmd = app.add_subcommand("tets", "Print the 72 reference tetrahedra of the hierarchy");
  auto json = std::make_shared<bool>(false);
  cmd->add_flag("--json", *json, "JSON output");
  cmd->callback([json, exit_code] {
    PrintTets(*json);
    *exit_code = 0;
  });
  return cmd;
}

}  // namespace isostream::cli
