/*
 * pose_logger: an ARGoS 3 loop function that writes what composed_sim's fidelity suite compares.
 *
 * Written for composed_sim (tests/fidelity, docs/fidelity.md); it uses only ARGoS's public
 * loop-function API. In the experiment file:
 *
 *   <loop_functions library="libpose_logger" label="pose_logger">
 *     <params output="run.csv" />
 *   </loop_functions>
 *
 * One CSV line per entity and logged tick:
 *   tick 0 (in Init, before any step): every robot and every box and cylinder, with its shape;
 *   every tick after a step (PostStep): every robot.
 * Columns: tick,kind,id,x,y,z,yaw,a,b,c
 *   kind  robot | box | cylinder
 *   yaw   rotation about z in radians
 *   a,b,c box: size x, y, z; cylinder: radius, height, 0; robot: 0, 0, 0
 * Positions are written with 17 significant digits, so the values are ARGoS's own doubles.
 */
#include <argos3/core/simulator/loop_functions.h>
#include <argos3/core/simulator/simulator.h>
#include <argos3/core/simulator/space/space.h>
#include <argos3/core/simulator/entity/composable_entity.h>
#include <argos3/core/simulator/entity/embodied_entity.h>
#include <argos3/core/simulator/entity/controllable_entity.h>
#include <argos3/core/utility/configuration/argos_configuration.h>
#include <argos3/plugins/simulator/entities/box_entity.h>
#include <argos3/plugins/simulator/entities/cylinder_entity.h>

#include <fstream>
#include <iomanip>
#include <string>

using namespace argos;

class CPoseLogger : public CLoopFunctions {

public:

   void Init(TConfigurationNode& t_tree) override {
      std::string strOutput = "poses.csv";
      if(NodeExists(t_tree, "params")) {
         GetNodeAttributeOrDefault(GetNode(t_tree, "params"), "output", strOutput, strOutput);
      }
      m_cOut.open(strOutput.c_str(), std::ios::out | std::ios::trunc);
      if(!m_cOut.good()) {
         THROW_ARGOSEXCEPTION("pose_logger: cannot write \"" << strOutput << "\"");
      }
      m_cOut << std::setprecision(17);
      m_cOut << "tick,kind,id,x,y,z,yaw,a,b,c" << std::endl;
      WriteTick(0, true);
   }

   void Reset() override {
      WriteTick(0, true);
   }

   void PostStep() override {
      WriteTick(GetSpace().GetSimulationClock(), false);
   }

   void Destroy() override {
      m_cOut.close();
   }

private:

   void WriteTick(UInt32 un_tick, bool b_with_objects) {
      for(CEntity* pcEntity : GetSpace().GetRootEntityVector()) {
         CComposableEntity* pcComposable = dynamic_cast<CComposableEntity*>(pcEntity);
         if(pcComposable == nullptr || !pcComposable->HasComponent("body")) continue;
         CEmbodiedEntity& cBody = pcComposable->GetComponent<CEmbodiedEntity>("body");
         Real fA = 0.0, fB = 0.0, fC = 0.0;
         std::string strKind;
         if(pcComposable->HasComponent("controller")) {
            strKind = "robot";
         }
         else if(CBoxEntity* pcBox = dynamic_cast<CBoxEntity*>(pcEntity)) {
            if(!b_with_objects) continue;
            strKind = "box";
            fA = pcBox->GetSize().GetX();
            fB = pcBox->GetSize().GetY();
            fC = pcBox->GetSize().GetZ();
         }
         else if(CCylinderEntity* pcCylinder = dynamic_cast<CCylinderEntity*>(pcEntity)) {
            if(!b_with_objects) continue;
            strKind = "cylinder";
            fA = pcCylinder->GetRadius();
            fB = pcCylinder->GetHeight();
         }
         else {
            continue;
         }
         const SAnchor& sOrigin = cBody.GetOriginAnchor();
         CRadians cYaw, cPitch, cRoll;
         sOrigin.Orientation.ToEulerAngles(cYaw, cPitch, cRoll);
         m_cOut << un_tick << ',' << strKind << ',' << pcEntity->GetId() << ','
                << sOrigin.Position.GetX() << ',' << sOrigin.Position.GetY() << ','
                << sOrigin.Position.GetZ() << ',' << cYaw.GetValue() << ','
                << fA << ',' << fB << ',' << fC << '\n';
      }
   }

   std::ofstream m_cOut;
};

REGISTER_LOOP_FUNCTIONS(CPoseLogger, "pose_logger")
