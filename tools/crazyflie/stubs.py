"""Stand-ins for the firmware headers the harness does not need for real (tools/crazyflie/regenerate.py).

The high-level commander, the planner, the polynomial trajectories and the commander's priority
queue are compiled from the firmware's own sources; what they include of the RTOS, the radio,
logging, parameters and the memory subsystem is replaced by these few lines each, written into
the build directory ahead of the firmware's include folders.
"""
from __future__ import annotations

HEADERS = {
    "FreeRTOS.h": """
#pragma once
#include <stdint.h>
#include <stddef.h>
#include <string.h>
uint64_t usecTimestamp(void);
typedef void *xSemaphoreHandle;
typedef int StaticSemaphore_t;
typedef long BaseType_t;
#define portMAX_DELAY 0
#define pdTRUE 1
#define M2T(X) ((unsigned int)(X))
""",
    "task.h": """
#pragma once
#include <stdint.h>
uint32_t xTaskGetTickCount(void);
""",
    "semphr.h": """
#pragma once
#define xSemaphoreTake(LOCK, WAIT) ((void)0)
#define xSemaphoreGive(LOCK) ((void)0)
#define xSemaphoreCreateMutexStatic(BUFFER) ((void *)(BUFFER))
""",
    "queue.h": """
#pragma once
""",
    "static_mem.h": """
#pragma once
#include <string.h>
typedef struct { size_t size; unsigned char item[1024]; } HarnessQueue;
typedef HarnessQueue *QueueHandle_t;
#define STATIC_MEM_TASK_ALLOC(NAME, STACK)
#define STATIC_MEM_TASK_CREATE(...)
#define STATIC_MEM_QUEUE_ALLOC(NAME, LENGTH, SIZE) static HarnessQueue NAME##Storage = {SIZE};
#define STATIC_MEM_QUEUE_CREATE(NAME) (&NAME##Storage)
#define xQueueSend(Q, ITEM, WAIT) (memcpy((Q)->item, (ITEM), (Q)->size), 1)
#define xQueueOverwrite(Q, ITEM) (memcpy((Q)->item, (ITEM), (Q)->size), 1)
#define xQueuePeek(Q, ITEM, WAIT) (memcpy((ITEM), (Q)->item, (Q)->size), 1)
""",
    "crtp.h": """
#pragma once
#include <stdint.h>
typedef struct { uint8_t size; uint8_t port; uint8_t channel; uint8_t data[30]; } CRTPPacket;
#define CRTP_PORT_SETPOINT_HL 0x08
#define crtpInitTaskQueue(PORT) ((void)0)
#define crtpReceivePacketBlock(PORT, P) ((void)0)
#define crtpSendPacketBlock(P) ((void)0)
#define crtpInit() ((void)0)
""",
    "log.h": """
#pragma once
#define LOG_GROUP_START(NAME)
#define LOG_GROUP_STOP(NAME)
#define LOG_ADD(...)
#define LOG_ADD_CORE(...)
""",
    "param.h": """
#pragma once
#define PARAM_GROUP_START(NAME)
#define PARAM_GROUP_STOP(NAME)
#define PARAM_ADD(...)
#define PARAM_ADD_CORE(...)
""",
    "config.h": "#pragma once\n",
    "cf_math.h": "#pragma once\n#include \"cfassert.h\"\n",
    "cfassert.h": "#pragma once\n#define ASSERT(E) ((void)0)\n",
    "stabilizer.h": "#pragma once\n",
    "debug.h": "#pragma once\n#define DEBUG_PRINT(...) ((void)0)\n",
    "arm_math.h": "#pragma once\n#define PI 3.14159265358979f\n",
}

# Compiled with ``-include`` before anything else for the double-precision build: the firmware's
# arithmetic, unchanged, with every ``float`` a ``double`` (its float literals stay as written).
DOUBLE_PRELUDE = """
#include <math.h>
#include <stdint.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <assert.h>
#define float double
#define M_PI_F M_PI
#define sqrtf sqrt
#define cosf cos
#define sinf sin
#define tanf tan
#define acosf acos
#define asinf asin
#define atan2f atan2
#define fabsf fabs
#define fmodf fmod
#define floorf floor
#define copysignf copysign
#define powf pow
#define fminf fmin
#define fmaxf fmax
#define expf exp
#define logf log
"""
