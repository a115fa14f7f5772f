#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "app/bench.h"

namespace toolbench::app {

/// `toolbench bench --protocol random --episodes N --seed S`: N full episodes (RunEpisode) with
/// randomized tools, cells and ball positions (episode i uses scene seed DeriveSeed(S, "random/i")),
/// each in its own child process, one results.jsonl line each (see RunSweep).
int RunRandomEpisodesBench(const BenchRequest& request);

/// The episode's choice judged against pulls in hindsight: `pulls` holds one object per tool of
/// the rack ({"tool", "ball_in_reach", "displacement_m", ...}, pull-gt's case for it). Returns
/// {"pulls", "best_tool" (in reach first, then the longest displacement), "in_reach" (how many
/// tools brought the ball into reach)} and, when at least one did, "correct" (the chosen tool is
/// one of them: every tool that brings the ball into reach does the episode's job, and a ball
/// moved far without reaching is most often one flung past the robot or off the table) and
/// "chance" (in_reach / tools: how often a random pick would be correct); with none in reach
/// there is no right choice and the choice is not judged. Throws std::invalid_argument for an
/// empty or malformed `pulls`.
nlohmann::json JudgeChoiceInHindsight(const nlohmann::json& pulls, const std::string& chosen_tool);

/// Why an assisted episode's robot was helped, from its result.json: the tool handed over after
/// the grasp stage ("hand-over: the handle out of reach" when no grasp was planned, "hand-over:
/// the grasp failed" when one moved and did not hold it), or the robot's own grip re-done by a
/// person ("re-grip: the look at the tool in the hand found none", "re-grip: no plan of the
/// action from the robot's own grip"); "other" otherwise.
std::string HelpReason(const nlohmann::json& result);

/// Writes summary.json and summary.md from random-episode results lines: success rates of grasp,
/// pull and ball grasp with 95 % Wilson intervals, assisted share and its reasons (help_reasons,
/// by HelpReason), stage-time medians and 90th percentiles, wall time per episode; with
/// --hindsight the choice's agreement with the best tool (choice_correct) beside a random pick's
/// (choice_correct_by_chance).
void ReportRandomEpisodes(const BenchRequest& request, const std::vector<SweepLine>& lines);

}  // namespace toolbench::app
