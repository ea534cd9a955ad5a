"""The OPC UA server (asyncua): the appliance as a machine of the OPC 40001 Machinery companion specifications."""
