/*
 * firmware_harness: drives the Crazyflie firmware's high-level commander from a line protocol.
 *
 * Written for composed_sim (tools/crazyflie/regenerate.py builds and runs it; nothing of the
 * firmware is in this repository). The build compiles this file with the firmware's own
 * src/modules/src/{crtp_commander_high_level,planner,pptraj,pptraj_compressed}.c included below,
 * against small stand-ins for the RTOS, radio, logging and parameter headers that
 * regenerate.py writes. The commander's static functions and variables are in this translation
 * unit, so a command is handed to its own dispatcher (handleCommand), with a group mask, exactly
 * as a radio packet's payload would be. The firmware's src/modules/src/commander.c (its own
 * translation unit) is the priority queue between the high-level commander and streamed setpoints;
 * "step" does what the stabilizer loop does with them.
 *
 * One command per input line; the lines that answer print one line:
 *   reset                                   the commander as after boot (planner idle, no trajectories)
 *   mask M                                  this drone's group mask (hlCommander.groupmask)
 *   time T                                  the clock, seconds (usecTimestamp = round(T * 1e6))
 *   state x y z vx vy vz yaw                the state estimate the commander reads (yaw in rad)
 *   tell                                    crtpCommanderHighLevelTellState(state)
 *   disable                                 crtpCommanderHighLevelDisable()
 *   block B                                 crtpCommanderBlock(B)
 *   takeoff MASK H YAW USECUR DUR           COMMAND_TAKEOFF_2             -> ret R
 *   land MASK H YAW USECUR DUR              COMMAND_LAND_2                -> ret R
 *   takeoffv MASK H REL YAW USECUR V        COMMAND_TAKEOFF_WITH_VELOCITY -> ret R
 *   landv MASK H REL YAW USECUR V           COMMAND_LAND_WITH_VELOCITY    -> ret R
 *   goto MASK REL LIN X Y Z YAW DUR         COMMAND_GO_TO_2               -> ret R
 *   stop MASK                               COMMAND_STOP                  -> ret R
 *   piece I DUR X0..X7 Y0..Y7 Z0..Z7 W0..W7 one poly4d written at piece slot I of the memory -> ret 0|1
 *   define ID OFFSET N                      COMMAND_DEFINE_TRAJECTORY (offset in pieces) -> ret R
 *   start MASK ID TIMESCALE REV RELPOS RELYAW  COMMAND_START_TRAJECTORY_2  -> ret R
 *   position X Y Z YAW                      a streamed position setpoint (as the generic
 *                                           commander decodes it), at the streams' priority
 *   fullstate X Y Z VX VY VZ AX AY AZ YAW   a streamed full-state setpoint, the same way (yaw in
 *                                           rad as the attitude; its quaternion is left out)
 *   hover VX VY YAWRATE Z                   a streamed hover setpoint (yaw rate in rad/s)
 *   notify                                  commanderRelaxPriority (notify setpoints stop)
 *   step                                    the stabilizer's commander part: the high-level
 *                                           commander's setpoint offered at its priority, then
 *                                           the commander's setpoint read ->
 *       sp GIVEN PRIORITY PLANNER_STATE MODE_X MODE_Z MODE_YAW
 *          px py pz vx vy vz ax ay az yaw wx wy wz    (yaw rad, body rates rad/s)
 * Numbers are printed with 17 significant digits.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <stdint.h>
#include <math.h>

static uint64_t harness_now_us;
uint64_t usecTimestamp(void) { return harness_now_us; }
uint32_t xTaskGetTickCount(void) { return (uint32_t)(harness_now_us / 1000); }

#include "crtp_commander_high_level.c"
#include "planner.c"
#include "pptraj.c"
#include "pptraj_compressed.c"
#include "commander.h"

void memoryRegisterHandler(const MemoryHandlerDef_t *def) { (void)def; }
void crtpCommanderInit(void) {}

static state_t harness_state;

static void reset_commander(void)
{
  memset(trajectories_memory, 0, sizeof(trajectories_memory));
  memset(trajectory_descriptions, 0, sizeof(trajectory_descriptions));
  memset(&harness_state, 0, sizeof(harness_state));
  isInit = false;
  commanderInit();
  group_mask = 0;
}

static void print_number(double v) { printf(" %.17g", v); }

static void step_commander(void)
{
  setpoint_t high_level, sp;
  memset(&high_level, 0, sizeof(high_level));
  bool given = crtpCommanderHighLevelGetSetpoint(&high_level, &harness_state, 0);
  if (given) {
    commanderSetSetpoint(&high_level, COMMANDER_PRIORITY_HIGHLEVEL);
  }
  commanderGetSetpoint(&sp, &harness_state);
  printf("sp %d %d %d %d %d %d", given ? 1 : 0, commanderGetActivePriority(), (int)planner.state,
         (int)sp.mode.x, (int)sp.mode.z, (int)sp.mode.yaw);
  double values[] = {
    sp.position.x, sp.position.y, sp.position.z,
    sp.velocity.x, sp.velocity.y, sp.velocity.z,
    sp.acceleration.x, sp.acceleration.y, sp.acceleration.z,
    radians(sp.attitude.yaw),
    radians(sp.attitudeRate.roll), radians(sp.attitudeRate.pitch), radians(sp.attitudeRate.yaw),
  };
  for (size_t i = 0; i < sizeof(values) / sizeof(values[0]); ++i) {
    print_number(values[i]);
  }
  printf("\n");
}

static int write_piece(char *rest)
{
  struct poly4d piece;
  int slot = (int)strtol(rest, &rest, 10);
  piece.duration = strtod(rest, &rest);
  for (int axis = 0; axis < 4; ++axis) {
    for (int k = 0; k < PP_SIZE; ++k) {
      piece.p[axis][k] = strtod(rest, &rest);
    }
  }
  return crtpCommanderHighLevelWriteTrajectory(slot * sizeof(struct poly4d), sizeof(piece),
                                               (const uint8_t *)&piece) ? 0 : 1;
}

/* A streamed setpoint, its fields set as the generic commander's decoders set them. */
static void stream_setpoint(const char *op, const double *a)
{
  static setpoint_t sp;
  memset(&sp, 0, sizeof(sp));
  if (strcmp(op, "hover") == 0) {
    sp.mode.x = modeVelocity; sp.mode.y = modeVelocity; sp.mode.z = modeAbs; sp.mode.yaw = modeVelocity;
    sp.velocity.x = a[0]; sp.velocity.y = a[1]; sp.attitudeRate.yaw = degrees(a[2]); sp.position.z = a[3];
    sp.velocity_body = true;
  } else {
    sp.mode.x = modeAbs; sp.mode.y = modeAbs; sp.mode.z = modeAbs; sp.mode.yaw = modeAbs;
    sp.position.x = a[0]; sp.position.y = a[1]; sp.position.z = a[2];
    if (strcmp(op, "position") == 0) {
      sp.attitude.yaw = degrees(a[3]);
    } else {
      sp.velocity.x = a[3]; sp.velocity.y = a[4]; sp.velocity.z = a[5];
      sp.acceleration.x = a[6]; sp.acceleration.y = a[7]; sp.acceleration.z = a[8];
      sp.attitude.yaw = degrees(a[9]);
    }
  }
  commanderSetSetpoint(&sp, COMMANDER_PRIORITY_CRTP);
}

static int read_numbers(char *p, double *out, int most)
{
  int n = 0;
  while (n < most) {
    char *end;
    double v = strtod(p, &end);
    if (end == p) break;
    out[n++] = v;
    p = end;
  }
  return n;
}

static int run_command(const char *op, char *rest)
{
  double a[8] = {0};
  if (strcmp(op, "piece") == 0) {
    return write_piece(rest);
  }
  read_numbers(rest, a, 8);
  if (strcmp(op, "takeoff") == 0 || strcmp(op, "land") == 0) {
    struct data_takeoff_2 d = {.groupMask = (uint8_t)a[0], .height = a[1], .yaw = a[2],
                               .useCurrentYaw = a[3] != 0, .duration = a[4]};
    return handleCommand(op[0] == 't' ? COMMAND_TAKEOFF_2 : COMMAND_LAND_2, (const uint8_t *)&d);
  }
  if (strcmp(op, "takeoffv") == 0 || strcmp(op, "landv") == 0) {
    struct data_takeoff_with_velocity d = {.groupMask = (uint8_t)a[0], .height = a[1],
                                           .heightIsRelative = a[2] != 0, .yaw = a[3],
                                           .useCurrentYaw = a[4] != 0, .velocity = a[5]};
    return handleCommand(op[0] == 't' ? COMMAND_TAKEOFF_WITH_VELOCITY : COMMAND_LAND_WITH_VELOCITY,
                         (const uint8_t *)&d);
  }
  if (strcmp(op, "goto") == 0) {
    struct data_go_to_2 d = {.groupMask = (uint8_t)a[0], .relative = (uint8_t)a[1], .linear = (uint8_t)a[2],
                             .x = a[3], .y = a[4], .z = a[5], .yaw = a[6], .duration = a[7]};
    return handleCommand(COMMAND_GO_TO_2, (const uint8_t *)&d);
  }
  if (strcmp(op, "stop") == 0) {
    struct data_stop d = {.groupMask = (uint8_t)a[0]};
    return handleCommand(COMMAND_STOP, (const uint8_t *)&d);
  }
  if (strcmp(op, "define") == 0) {
    struct data_define_trajectory d;
    memset(&d, 0, sizeof(d));
    d.trajectoryId = (uint8_t)a[0];
    d.description.trajectoryLocation = TRAJECTORY_LOCATION_MEM;
    d.description.trajectoryType = CRTP_CHL_TRAJECTORY_TYPE_POLY4D;
    d.description.trajectoryIdentifier.mem.offset = (uint32_t)a[1] * sizeof(struct poly4d);
    d.description.trajectoryIdentifier.mem.n_pieces = (uint8_t)a[2];
    return handleCommand(COMMAND_DEFINE_TRAJECTORY, (const uint8_t *)&d);
  }
  if (strcmp(op, "start") == 0) {
    struct data_start_trajectory_2 d = {.groupMask = (uint8_t)a[0], .trajectoryId = (uint8_t)a[1],
                                        .timescale = a[2], .reversed = (uint8_t)a[3],
                                        .relativePosition = (uint8_t)a[4], .relativeYaw = (uint8_t)a[5]};
    return handleCommand(COMMAND_START_TRAJECTORY_2, (const uint8_t *)&d);
  }
  fprintf(stderr, "firmware_harness: unknown command %s\n", op);
  exit(2);
}

int main(void)
{
  char line[4096];
  reset_commander();
  while (fgets(line, sizeof(line), stdin)) {
    char op[32];
    int used = 0;
    if (sscanf(line, "%31s%n", op, &used) != 1) continue;
    char *rest = line + used;
    double a[12] = {0};
    if (strcmp(op, "reset") == 0) {
      reset_commander();
    } else if (strcmp(op, "mask") == 0) {
      group_mask = (uint8_t)strtol(rest, NULL, 10);
    } else if (strcmp(op, "time") == 0) {
      harness_now_us = (uint64_t)llround(strtod(rest, NULL) * 1e6);
    } else if (strcmp(op, "state") == 0) {
      sscanf(rest, "%lf %lf %lf %lf %lf %lf %lf", &a[0], &a[1], &a[2], &a[3], &a[4], &a[5], &a[6]);
      harness_state.position.x = a[0]; harness_state.position.y = a[1]; harness_state.position.z = a[2];
      harness_state.velocity.x = a[3]; harness_state.velocity.y = a[4]; harness_state.velocity.z = a[5];
      harness_state.attitude.yaw = degrees(a[6]);
    } else if (strcmp(op, "tell") == 0) {
      crtpCommanderHighLevelTellState(&harness_state);
    } else if (strcmp(op, "disable") == 0) {
      crtpCommanderHighLevelDisable();
    } else if (strcmp(op, "block") == 0) {
      crtpCommanderBlock(strtol(rest, NULL, 10) != 0);
    } else if (strcmp(op, "position") == 0 || strcmp(op, "fullstate") == 0 || strcmp(op, "hover") == 0) {
      read_numbers(rest, a, 12);
      stream_setpoint(op, a);
    } else if (strcmp(op, "notify") == 0) {
      commanderRelaxPriority();
    } else if (strcmp(op, "step") == 0) {
      step_commander();
    } else {
      printf("ret %d\n", run_command(op, rest));
    }
    fflush(stdout);
  }
  return 0;
}
